/* SPDX-License-Identifier: MIT */
/* FaultHold: the timed fault bit every daemon fault with a hold uses (firmware/fault_hold.h). */
#include <gtest/gtest.h>

#include "firmware/fault_hold.h"

using dockpose::firmware::FaultHold;

namespace {
constexpr std::int64_t kHoldNs = 1000;
} /* namespace */

TEST(FaultHold, StartsClearAndHoldsForItsTimeAfterTheLastEvent)
{
	FaultHold f(kHoldNs);
	EXPECT_FALSE(f.active(1));
	f.raise(5000);
	EXPECT_TRUE(f.active(5000));
	EXPECT_TRUE(f.active(5999));
	EXPECT_FALSE(f.active(6000)) << "held for exactly hold_ns";
	f.raise(5500); /* a second event: held for hold_ns from it */
	EXPECT_TRUE(f.active(6499));
	EXPECT_FALSE(f.active(6500));
}

TEST(FaultHold, RaisesWhenACountMovesAndOnlyThen)
{
	FaultHold f(kHoldNs);
	f.raiseOnChange(0, 100); /* the count every backend starts at: nothing happened */
	EXPECT_FALSE(f.active(100));
	f.raiseOnChange(3, 200);
	EXPECT_TRUE(f.active(200));
	f.raiseOnChange(3, 1100); /* unchanged: the hold runs out from 200 */
	EXPECT_TRUE(f.active(1199));
	EXPECT_FALSE(f.active(1200));
	f.raiseOnChange(4, 5000);
	EXPECT_TRUE(f.active(5999));
	EXPECT_FALSE(f.active(6000));
}
