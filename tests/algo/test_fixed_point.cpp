/* SPDX-License-Identifier: MIT */
/*
 * Fixed-point types: construction, rounding, saturation, arithmetic against
 * exact integer references.
 */
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "algo/fixed_point.h"

using namespace dockpose;

namespace {

/* Reference: p / 2^shift rounded to nearest, halves away from zero, by division and remainder. */
std::int64_t refRoundShift(std::int64_t p, int shift)
{
	const std::int64_t d = std::int64_t{ 1 } << shift;
	std::int64_t q = p / d; /* truncates toward zero */
	const std::int64_t rem = p % d;
	const std::int64_t abs_rem = rem < 0 ? -rem : rem;
	if (2 * abs_rem >= d)
		q += p < 0 ? -1 : 1;
	return q;
}

template<typename F>
std::int64_t refSaturate(std::int64_t raw)
{
	const std::int64_t lo = std::numeric_limits<typename F::rep>::min();
	const std::int64_t hi = std::numeric_limits<typename F::rep>::max();
	return raw < lo ? lo : (raw > hi ? hi : raw);
}

} /* namespace */

TEST(FixedPoint, FormatsAndRanges)
{
	static_assert(sizeof(UQ8_8) == 2 && sizeof(Q16_16) == 4 && sizeof(UQ16_16) == 4);
	static_assert(UQ8_8::kFracBits == 8 && Q16_16::kFracBits == 16 && UQ16_16::kIntBits == 16);
	EXPECT_DOUBLE_EQ(UQ8_8::max().toDouble(), 65535.0 / 256.0);
	EXPECT_DOUBLE_EQ(UQ8_8::lowest().toDouble(), 0.0);
	EXPECT_DOUBLE_EQ(Q16_16::max().toDouble(), 2147483647.0 / 65536.0);
	EXPECT_DOUBLE_EQ(Q16_16::lowest().toDouble(), -32768.0);
	EXPECT_DOUBLE_EQ(Q8_8::lowest().toDouble(), -128.0);
	EXPECT_DOUBLE_EQ(UQ8_8::epsilon().toDouble(), 1.0 / 256.0);
}

TEST(FixedPoint, ConstexprConstruction)
{
	constexpr UQ8_8 a(6);
	constexpr UQ8_8 b(1.5);
	constexpr Q16_16 c(-2.25);
	static_assert(a.raw() == 6 * 256);
	static_assert(b.raw() == 384);
	static_assert(c.raw() == -2 * 65536 - 16384);
	static_assert((a * b).raw() == 9 * 256);
	static_assert(Q16_16(-7).toIntFloor() == -7);
	EXPECT_EQ((a + b).toDouble(), 7.5);
}

TEST(FixedPoint, DoubleConstructionRoundsToNearest)
{
	/* 1/256 = 0.00390625: half a step is 0.001953125 */
	EXPECT_EQ(UQ8_8(0.001953125).raw(), 1); /* exactly half: away from zero */
	EXPECT_EQ(UQ8_8(0.0019).raw(), 0);
	EXPECT_EQ(UQ8_8(0.0020).raw(), 1);
	EXPECT_EQ(Q8_8(-0.001953125).raw(), -1); /* halves away from zero for negatives */
	EXPECT_EQ(Q8_8(-0.0019).raw(), 0);
	EXPECT_EQ(Q16_16(1.4826).raw(), 97164); /* 1.4826 * 65536 = 97163.67 */
	EXPECT_EQ(Q16_16(1.4826).raw(), std::lround(1.4826 * 65536.0));

	std::mt19937_64 rng(7);
	std::uniform_real_distribution<double> dist(-30000.0, 30000.0);
	for (int i = 0; i < 10000; ++i) {
		const double v = dist(rng);
		const Q16_16 f(v);
		EXPECT_LE(std::abs(f.toDouble() - v), 0.5 / 65536.0 + 1e-12) << v;
		EXPECT_EQ(f.raw(), std::llround(v * 65536.0)) << v;
	}
}

TEST(FixedPoint, ConstructionSaturates)
{
	EXPECT_EQ(UQ8_8(300), UQ8_8::max());
	EXPECT_EQ(UQ8_8(256), UQ8_8::max());
	EXPECT_EQ(UQ8_8(255).raw(), 255 * 256);
	EXPECT_EQ(UQ8_8(-1), UQ8_8::lowest());
	EXPECT_EQ(UQ8_8(-0.7), UQ8_8(0));
	EXPECT_EQ(UQ8_8(1e30), UQ8_8::max());
	EXPECT_EQ(Q16_16(40000.0), Q16_16::max());
	EXPECT_EQ(Q16_16(-40000.0), Q16_16::lowest());
	EXPECT_EQ(Q16_16(-32768), Q16_16::lowest());
	EXPECT_EQ(Q16_16(std::numeric_limits<std::int64_t>::max()), Q16_16::max());
	EXPECT_EQ(Q16_16(std::numeric_limits<std::int64_t>::min()), Q16_16::lowest());
	EXPECT_EQ(UQ16_16(std::numeric_limits<std::uint64_t>::max()), UQ16_16::max());
	EXPECT_EQ(Q16_16(std::nan("")).raw(), 0);
	EXPECT_EQ(UQ16_16(std::numeric_limits<double>::infinity()), UQ16_16::max());
}

TEST(FixedPoint, IntegerConversions)
{
	EXPECT_EQ(Q16_16(2.5).toIntFloor(), 2);
	EXPECT_EQ(Q16_16(2.5).toIntCeil(), 3);
	EXPECT_EQ(Q16_16(2.5).toIntRound(), 3);
	EXPECT_EQ(Q16_16(2.49).toIntRound(), 2);
	EXPECT_EQ(Q16_16(-2.5).toIntFloor(), -3);
	EXPECT_EQ(Q16_16(-2.5).toIntCeil(), -2);
	EXPECT_EQ(Q16_16(-2.5).toIntRound(), -3);
	EXPECT_EQ(Q16_16(-2.49).toIntRound(), -2);
	EXPECT_EQ(Q16_16(-3).toIntCeil(), -3);
	EXPECT_EQ(Q16_16(-3).toIntFloor(), -3);
	EXPECT_EQ(UQ8_8::max().toIntRound(), 256);
	EXPECT_EQ(UQ8_8::max().toIntFloor(), 255);
	EXPECT_EQ(UQ16_16::max().toIntCeil(), 65536);
	EXPECT_EQ(Q16_16(7).toInt(), 7);

	std::mt19937 rng(3);
	std::uniform_int_distribution<std::int32_t> raw(std::numeric_limits<std::int32_t>::min(),
							std::numeric_limits<std::int32_t>::max());
	for (int i = 0; i < 10000; ++i) {
		const Q16_16 f = Q16_16::fromRaw(raw(rng));
		const double d = f.toDouble();
		EXPECT_EQ(f.toIntFloor(), static_cast<std::int64_t>(std::floor(d)));
		EXPECT_EQ(f.toIntCeil(), static_cast<std::int64_t>(std::ceil(d)));
		/* std::round: halves away from zero */
		EXPECT_EQ(f.toIntRound(), static_cast<std::int64_t>(std::round(d)));
	}
}

TEST(FixedPoint, AddSubSaturate)
{
	EXPECT_EQ(UQ8_8(200) + UQ8_8(100), UQ8_8::max());
	EXPECT_EQ(UQ8_8(3) - UQ8_8(5), UQ8_8(0));
	EXPECT_EQ((UQ8_8(5) - UQ8_8(3)).raw(), 2 * 256);
	EXPECT_EQ(Q16_16(30000) + Q16_16(30000), Q16_16::max());
	EXPECT_EQ(Q16_16(-30000) - Q16_16(30000), Q16_16::lowest());
	EXPECT_EQ(-Q16_16::lowest(), Q16_16::max());
	EXPECT_EQ((-Q16_16(1.5)).toDouble(), -1.5);
	UQ16_16 acc;
	for (int i = 0; i < 10; ++i)
		acc += UQ16_16(0.1);
	EXPECT_EQ(acc.raw(), 10 * UQ16_16(0.1).raw());
}

TEST(FixedPoint, MultiplyRoundsLikeExactReference)
{
	std::mt19937 rng(11);
	std::uniform_int_distribution<std::int32_t> raw32(std::numeric_limits<std::int32_t>::min(),
							  std::numeric_limits<std::int32_t>::max());
	for (int i = 0; i < 20000; ++i) {
		const Q16_16 a = Q16_16::fromRaw(raw32(rng) >> (i % 17));
		const Q16_16 b = Q16_16::fromRaw(raw32(rng) >> (i % 13));
		const std::int64_t p = static_cast<std::int64_t>(a.raw()) * b.raw();
		const std::int64_t expected = refSaturate<Q16_16>(refRoundShift(p, 16));
		ASSERT_EQ((a * b).raw(), expected) << a.raw() << " * " << b.raw();
	}
	std::uniform_int_distribution<int> raw16(0, 65535);
	for (int i = 0; i < 20000; ++i) {
		const UQ8_8 a = UQ8_8::fromRaw(static_cast<std::uint16_t>(raw16(rng) >> (i % 9)));
		const UQ8_8 b = UQ8_8::fromRaw(static_cast<std::uint16_t>(raw16(rng) >> (i % 7)));
		const std::int64_t p = static_cast<std::int64_t>(a.raw()) * b.raw();
		ASSERT_EQ((a * b).raw(), refSaturate<UQ8_8>(refRoundShift(p, 8)));
	}
	EXPECT_EQ((UQ8_8(6) * UQ8_8(2.0)).toDouble(), 12.0);
	EXPECT_EQ(UQ8_8(100) * UQ8_8(100), UQ8_8::max());
	EXPECT_EQ(Q16_16(-300) * Q16_16(300), Q16_16::lowest());
}

TEST(FixedPoint, MulIntAndDivide)
{
	EXPECT_EQ(UQ8_8(1.5).mulInt(3).toDouble(), 4.5);
	EXPECT_EQ(UQ8_8(1.5).mulInt(-3), UQ8_8(0));
	EXPECT_EQ(Q16_16(-1.25).mulInt(4).toDouble(), -5.0);
	EXPECT_EQ(Q16_16(2).mulInt(1000000), Q16_16::max());
	EXPECT_EQ(Q16_16(2).mulInt(-1000000), Q16_16::lowest());

	EXPECT_EQ((Q16_16(1) / Q16_16(3)).raw(), 21845); /* 65536 / 3 = 21845.33 */
	EXPECT_EQ((Q16_16(2) / Q16_16(3)).raw(), 43691); /* 43690.67 */
	EXPECT_EQ((Q16_16(-2) / Q16_16(3)).raw(), -43691);
	EXPECT_EQ((Q16_16(1) / Q16_16(0)), Q16_16::max());
	EXPECT_EQ((Q16_16(-1) / Q16_16(0)), Q16_16::lowest());
	EXPECT_EQ((UQ8_8(200) / UQ8_8(0.5)), UQ8_8::max());

	std::mt19937 rng(5);
	std::uniform_int_distribution<std::int32_t> raw32(-(1 << 30), 1 << 30);
	for (int i = 0; i < 20000; ++i) {
		const Q16_16 a = Q16_16::fromRaw(raw32(rng));
		Q16_16 b = Q16_16::fromRaw(raw32(rng) >> (i % 20));
		if (b.raw() == 0)
			b = Q16_16::epsilon();
		/* reference: round(a * 2^16 / b), halves away from zero, by division and remainder */
		const std::int64_t n = static_cast<std::int64_t>(a.raw()) * 65536;
		const std::int64_t d = b.raw();
		std::int64_t q = n / d;
		const std::int64_t rem = n % d;
		if (2 * (rem < 0 ? -rem : rem) >= (d < 0 ? -d : d))
			q += ((n < 0) != (d < 0)) ? -1 : 1;
		ASSERT_EQ((a / b).raw(), refSaturate<Q16_16>(q)) << a.raw() << " / " << b.raw();
	}
}

TEST(FixedPoint, MixedFormats)
{
	/* k (UQ8_8) times sigma (UQ16_16) into UQ16_16: the threshold contrast. */
	const UQ8_8 k(6.0);
	const UQ16_16 sigma(2.0625);
	EXPECT_EQ(fixedMul<UQ16_16>(k, sigma).toDouble(), 12.375);

	std::mt19937 rng(9);
	std::uniform_int_distribution<std::uint32_t> r16(0, 65535);
	std::uniform_int_distribution<std::uint32_t> r32(0, 0xffffffffu);
	for (int i = 0; i < 20000; ++i) {
		const UQ8_8 a = UQ8_8::fromRaw(static_cast<std::uint16_t>(r16(rng)));
		const UQ16_16 b = UQ16_16::fromRaw(r32(rng) >> (i % 32));
		const std::int64_t p =
			static_cast<std::int64_t>(a.raw()) * static_cast<std::int64_t>(b.raw());
		ASSERT_EQ(fixedMul<UQ16_16>(a, b).raw(), refSaturate<UQ16_16>(refRoundShift(p, 8)));
		/* into a signed format with fewer fraction bits */
		ASSERT_EQ(fixedMul<Q24_8>(a, b).raw(), refSaturate<Q24_8>(refRoundShift(p, 16)));
	}
	/* Signed into unsigned saturates at zero. */
	EXPECT_EQ(fixedMul<UQ16_16>(Q16_16(-2), UQ16_16(3)), UQ16_16(0));
	/* As many and more fraction bits in the result than in the product. */
	EXPECT_EQ(fixedMul<UQ16_16>(UQ24_8(3.5), UQ24_8(2.0)).toDouble(), 7.0);
	using UQ28_4 = Fixed<28, 4, std::uint32_t>;
	using Q28_4 = Fixed<28, 4, std::int32_t>;
	EXPECT_EQ(fixedMul<UQ16_16>(UQ28_4(3.5), UQ28_4(2.0)).toDouble(), 7.0);
	EXPECT_EQ(fixedMul<Q16_16>(Q28_4(-3.5), Q28_4(2.0)).toDouble(), -7.0);
	EXPECT_EQ(fixedMul<Q16_16>(Q28_4(-300.0), Q28_4(200.0)), Q16_16::lowest());
	EXPECT_EQ(fixedMul<UQ16_16>(UQ28_4(300.0), UQ28_4(300.0)), UQ16_16::max());
	/* Two large unsigned values into a signed result saturate instead of wrapping. */
	EXPECT_EQ(fixedMul<Q16_16>(UQ16_16::max(), UQ16_16::max()), Q16_16::max());

	EXPECT_EQ(fixedCast<UQ8_8>(UQ16_16(1.5)).toDouble(), 1.5);
	EXPECT_EQ(fixedCast<UQ8_8>(UQ16_16(1000.0)), UQ8_8::max());
	EXPECT_EQ(fixedCast<UQ8_8>(Q16_16(-1.0)), UQ8_8(0));
	EXPECT_EQ(fixedCast<Q16_16>(UQ8_8(2.75)).toDouble(), 2.75);
	/* half of the UQ8_8 step: away from 0 */
	EXPECT_EQ(fixedCast<UQ8_8>(UQ16_16::fromRaw(128)).raw(), 1);
	EXPECT_EQ(fixedCast<UQ8_8>(UQ16_16::fromRaw(127)).raw(), 0);
}

TEST(FixedPoint, Comparisons)
{
	EXPECT_LT(Q16_16(-1), Q16_16(0.5));
	EXPECT_GT(UQ8_8(2), UQ8_8(1.99));
	EXPECT_EQ(UQ8_8(1.0), UQ8_8(1));
	EXPECT_NE(UQ8_8(1.0), UQ8_8(1.01));
}
