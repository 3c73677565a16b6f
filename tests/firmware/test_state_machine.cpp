/* SPDX-License-Identifier: MIT */
#include <gtest/gtest.h>

#include "firmware/state_machine.h"

namespace dockpose::firmware {
namespace {

using can::SensorState;
namespace fault = can::fault;

TEST(StateMachine, StartsInStartupAndSearchesUntilAPose)
{
	StateMachine sm(3, 5);
	EXPECT_EQ(sm.state(), SensorState::Startup);
	EXPECT_EQ(sm.update({ false, 0 }), SensorState::Searching);
	EXPECT_EQ(sm.update({ false, 0 }), SensorState::Searching);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Tracking);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Tracking);
}

TEST(StateMachine, ShortLossIsDegradedLongLossIsSearching)
{
	StateMachine sm(3, 0);
	sm.update({ true, 0 });
	EXPECT_EQ(sm.update({ false, 0 }), SensorState::Degraded);
	EXPECT_EQ(sm.update({ false, 0 }), SensorState::Degraded);
	EXPECT_EQ(sm.update({ false, 0 }), SensorState::Searching);
	EXPECT_EQ(sm.framesSinceValid(), 3);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Tracking);
}

TEST(StateMachine, DegradingFaultsHoldDegradedForTheHoldFrames)
{
	StateMachine sm(3, 2);
	sm.update({ true, 0 });
	EXPECT_EQ(sm.update({ true, fault::kFramesDropped }), SensorState::Degraded);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Degraded);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Degraded);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Tracking);
	EXPECT_EQ(sm.update({ true, fault::kCanTxOverflow }), SensorState::Degraded);
}

TEST(StateMachine, FatalFaultsMeanFaultAndRecoverThroughSearching)
{
	StateMachine sm(3, 0);
	sm.update({ true, 0 });
	EXPECT_EQ(sm.update({ true, fault::kCameraStall }), SensorState::Fault);
	EXPECT_EQ(sm.update({ false, fault::kCameraError }), SensorState::Fault);
	EXPECT_EQ(sm.update({ false, 0 }), SensorState::Searching);
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Tracking);
}

TEST(StateMachine, ShutdownIsFinal)
{
	StateMachine sm(3, 0);
	sm.update({ true, 0 });
	sm.shutdown();
	EXPECT_EQ(sm.update({ true, 0 }), SensorState::Shutdown);
}

} /* namespace */
} /* namespace dockpose::firmware */
