/* SPDX-License-Identifier: MIT */
/*
 * Fixed-point numbers with the Q format in the type name.
 *
 * Fixed<IntBits, FracBits, Rep> stores value * 2^FracBits in the integer Rep.
 * IntBits + FracBits is the width of Rep; for a signed Rep, IntBits counts the
 * sign bit (Q16_16 is an int32 with 16 fraction bits, range [-32768, 32768);
 * UQ8_8 is a uint16 with 8 fraction bits, range [0, 256)).
 *
 * Semantics:
 *  - construction from an integer or a double is constexpr, rounds to the
 *    nearest representable value (halves away from zero) and saturates;
 *    NaN becomes 0;
 *  - +, -, *, / saturate at the range of the type instead of wrapping;
 *  - * and / round to nearest (halves away from zero), exact in between:
 *    the product or quotient is formed in 64 bits;
 *  - fixedMul<R>(a, b) multiplies two different formats into a third one,
 *    fixedCast<R>(a) converts between formats, both rounding and saturating.
 *
 * Allocates: never. Everything is constexpr.
 */
#pragma once

#include <compare>
#include <concepts>
#include <cstdint>
#include <limits>
#include <type_traits>

namespace dockpose {

namespace fixed_detail {

/* Signed and unsigned 64-bit intermediates. */
template<typename Rep>
using Wide = std::conditional_t<std::is_signed_v<Rep>, std::int64_t, std::uint64_t>;

/* a / b rounded to nearest, halves away from zero; b != 0. */
constexpr std::int64_t divRound(std::int64_t a, std::int64_t b)
{
	const bool negative = (a < 0) != (b < 0);
	const std::uint64_t ua = a < 0 ? 0 - static_cast<std::uint64_t>(a)
				       : static_cast<std::uint64_t>(a);
	const std::uint64_t ub = b < 0 ? 0 - static_cast<std::uint64_t>(b)
				       : static_cast<std::uint64_t>(b);
	const std::uint64_t q = (ua + ub / 2) / ub;
	return negative ? -static_cast<std::int64_t>(q) : static_cast<std::int64_t>(q);
}

constexpr std::uint64_t divRound(std::uint64_t a, std::uint64_t b)
{
	return (a + b / 2) / b;
}

/* v / 2^shift rounded to nearest, halves away from zero (shift in [1, 62]). */
constexpr std::int64_t shiftRound(std::int64_t v, int shift)
{
	const std::int64_t half = std::int64_t{ 1 } << (shift - 1);
	if (v >= 0)
		return (v + half) >> shift;
	return -((-v + half) >> shift);
}

constexpr std::uint64_t shiftRound(std::uint64_t v, int shift)
{
	const std::uint64_t half = std::uint64_t{ 1 } << (shift - 1);
	/* Avoid overflow of v + half at the top of the range. */
	return (v >> shift) + ((v & ((half << 1) - 1)) >= half ? 1 : 0);
}

} /* namespace fixed_detail */

template<int IntBits, int FracBits, typename Rep>
class Fixed
{
	static_assert(std::is_integral_v<Rep> && !std::is_same_v<Rep, bool>,
		      "Rep must be an integer type");
	static_assert(sizeof(Rep) <= 4, "products and quotients are formed in 64 bits");
	static_assert(IntBits >= 0 && FracBits >= 1, "need at least one fraction bit");
	static_assert(
		IntBits + FracBits ==
			std::numeric_limits<Rep>::digits + (std::is_signed_v<Rep> ? 1 : 0),
		"IntBits + FracBits must be the width of Rep (the sign bit counts as an integer bit)");

public:
	using rep = Rep;
	using wide = fixed_detail::Wide<Rep>;

	static constexpr int kIntBits = IntBits;
	static constexpr int kFracBits = FracBits;
	static constexpr bool kSigned = std::is_signed_v<Rep>;
	static constexpr wide kOneRaw = wide{ 1 } << FracBits;
	static constexpr wide kRawMax = std::numeric_limits<Rep>::max();
	static constexpr wide kRawMin = std::numeric_limits<Rep>::min();

	constexpr Fixed() = default;

	/* From an integer, saturating. */
	template<std::integral T>
	constexpr explicit Fixed(T value)
		: raw_(fromIntRaw(value))
	{
	}

	/* From a floating-point value, rounded to nearest and saturating. */
	template<std::floating_point T>
	constexpr explicit Fixed(T value)
		: raw_(fromDoubleRaw(static_cast<double>(value)))
	{
	}

	static constexpr Fixed fromRaw(Rep raw)
	{
		Fixed f;
		f.raw_ = raw;
		return f;
	}

	/* A raw value in the wide type, saturated into Rep. */
	static constexpr Fixed fromWideRaw(wide raw) { return fromRaw(saturate(raw)); }

	static constexpr Fixed max() { return fromRaw(std::numeric_limits<Rep>::max()); }
	static constexpr Fixed lowest() { return fromRaw(std::numeric_limits<Rep>::min()); }
	/* The smallest positive step, 2^-FracBits. */
	static constexpr Fixed epsilon() { return fromRaw(1); }

	constexpr Rep raw() const { return raw_; }

	/* Largest integer <= value. */
	constexpr std::int64_t toIntFloor() const
	{
		return static_cast<std::int64_t>(static_cast<wide>(raw_) >> FracBits);
	}

	/* Smallest integer >= value. */
	constexpr std::int64_t toIntCeil() const
	{
		return static_cast<std::int64_t>((static_cast<wide>(raw_) + (kOneRaw - 1)) >>
						 FracBits);
	}

	/* Nearest integer, halves away from zero. */
	constexpr std::int64_t toIntRound() const
	{
		return static_cast<std::int64_t>(
			fixed_detail::shiftRound(static_cast<wide>(raw_), FracBits));
	}

	/* The same as toIntFloor(). */
	constexpr std::int64_t toInt() const { return toIntFloor(); }

	constexpr double toDouble() const
	{
		return static_cast<double>(raw_) / static_cast<double>(kOneRaw);
	}

	constexpr Fixed operator+(Fixed other) const
	{
		return fromWideRaw(static_cast<wide>(raw_) + static_cast<wide>(other.raw_));
	}

	constexpr Fixed operator-(Fixed other) const
	{
		if constexpr (kSigned)
			return fromWideRaw(static_cast<wide>(raw_) - static_cast<wide>(other.raw_));
		else
			return raw_ >= other.raw_ ? fromRaw(static_cast<Rep>(raw_ - other.raw_))
						  : fromRaw(0);
	}

	constexpr Fixed operator-() const
	{
		if constexpr (kSigned)
			return fromWideRaw(-static_cast<wide>(raw_));
		else
			return fromRaw(0);
	}

	/* Product rounded to nearest, saturating. */
	constexpr Fixed operator*(Fixed other) const
	{
		const wide p = static_cast<wide>(raw_) * static_cast<wide>(other.raw_);
		return fromWideRaw(fixed_detail::shiftRound(p, FracBits));
	}

	/* Product with an integer, saturating. */
	template<std::integral T>
	constexpr Fixed mulInt(T factor) const
	{
		/* |raw| < 2^32 and |factor| <= 2^31: the product fits in 64 bits. */
		constexpr wide lo = kSigned ? -(wide{ 1 } << 31) : wide{ 0 };
		const wide f = clampInt(factor, lo, wide{ 1 } << 31);
		return fromWideRaw(static_cast<wide>(raw_) * f);
	}

	/* Quotient rounded to nearest, saturating; division by zero saturates. */
	constexpr Fixed operator/(Fixed other) const
	{
		if (other.raw_ == 0) {
			if constexpr (kSigned)
				return raw_ < 0 ? lowest() : (raw_ == 0 ? Fixed() : max());
			else
				return raw_ == 0 ? Fixed() : max();
		}
		const wide n = static_cast<wide>(raw_) * kOneRaw;
		return fromWideRaw(fixed_detail::divRound(n, static_cast<wide>(other.raw_)));
	}

	constexpr Fixed &operator+=(Fixed other) { return *this = *this + other; }
	constexpr Fixed &operator-=(Fixed other) { return *this = *this - other; }
	constexpr Fixed &operator*=(Fixed other) { return *this = *this * other; }
	constexpr Fixed &operator/=(Fixed other) { return *this = *this / other; }

	/* NOLINTNEXTLINE(modernize-use-nullptr): clang-tidy 14 on a defaulted <=> */
	constexpr auto operator<=>(const Fixed &) const = default;
	constexpr bool operator==(const Fixed &) const = default;

private:
	template<typename T>
	static constexpr wide clampInt(T v, wide lo, wide hi)
	{
		if constexpr (std::is_signed_v<T>) {
			const std::int64_t s = static_cast<std::int64_t>(v);
			if constexpr (std::is_signed_v<wide>) {
				return s < lo ? lo : (s > hi ? hi : s);
			} else {
				if (s < 0)
					return lo;
				const std::uint64_t u = static_cast<std::uint64_t>(s);
				return u < lo ? lo : (u > hi ? hi : u);
			}
		} else {
			const std::uint64_t u = static_cast<std::uint64_t>(v);
			if constexpr (std::is_signed_v<wide>) {
				if (u > static_cast<std::uint64_t>(
						std::numeric_limits<std::int64_t>::max()))
					return hi;
				const std::int64_t s = static_cast<std::int64_t>(u);
				return s < lo ? lo : (s > hi ? hi : s);
			} else {
				return u < lo ? lo : (u > hi ? hi : u);
			}
		}
	}

	static constexpr Rep saturate(wide raw)
	{
		if (raw > kRawMax)
			return std::numeric_limits<Rep>::max();
		if (raw < kRawMin)
			return std::numeric_limits<Rep>::min();
		return static_cast<Rep>(raw);
	}

	template<typename T>
	static constexpr Rep fromIntRaw(T value)
	{
		/* Clamp to the representable integer range first: no overflow in the shift. */
		const wide lo = kRawMin >> FracBits;
		const wide hi = (kRawMax >> FracBits) + 1;
		return saturate(clampInt(value, lo, hi) * kOneRaw);
	}

	static constexpr Rep fromDoubleRaw(double value)
	{
		if (value != value)
			return 0;
		const double scaled = value * static_cast<double>(kOneRaw);
		if (scaled >= static_cast<double>(kRawMax))
			return std::numeric_limits<Rep>::max();
		if (scaled <= static_cast<double>(kRawMin))
			return std::numeric_limits<Rep>::min();
		const double rounded = scaled >= 0.0 ? scaled + 0.5 : scaled - 0.5;
		return saturate(static_cast<wide>(rounded));
	}

	Rep raw_ = 0;
};

template<typename T>
struct IsFixed : std::false_type {
};
template<int I, int F, typename R>
struct IsFixed<Fixed<I, F, R>> : std::true_type {
};

/*
 * a * b in the format R, rounded to nearest and saturating. The raw product
 * must fit in 64 bits (it does for any two formats of up to 32 bits).
 */
template<typename R, typename A, typename B>
requires(IsFixed<R>::value &&IsFixed<A>::value &&IsFixed<B>::value) constexpr R fixedMul(A a, B b)
{
	/* Both raw values have at most 32 bits: the product fits in 64 bits. */
	using W = std::conditional_t<A::kSigned || B::kSigned, std::int64_t, std::uint64_t>;
	const W p = static_cast<W>(a.raw()) * static_cast<W>(b.raw());
	constexpr int shift = A::kFracBits + B::kFracBits - R::kFracBits;
	W r = p;
	if constexpr (shift > 0) {
		r = fixed_detail::shiftRound(p, shift);
	} else if constexpr (shift < 0) {
		/* More fraction bits than the product: exact unless it overflows. */
		constexpr W limit = std::numeric_limits<W>::max() >> (-shift);
		if (p > limit)
			return R::max();
		if constexpr (std::is_signed_v<W>) {
			if (p < -limit)
				return R::lowest();
		}
		r = p * (W{ 1 } << (-shift));
	}
	if constexpr (std::is_signed_v<W>) {
		if (r < 0) {
			if constexpr (!R::kSigned)
				return R::fromRaw(0);
			else
				return R::fromWideRaw(r);
		}
	}
	/* r >= 0 here. */
	const std::uint64_t u = static_cast<std::uint64_t>(r);
	if (u > static_cast<std::uint64_t>(R::kRawMax))
		return R::max();
	return R::fromRaw(static_cast<typename R::rep>(u));
}

/* a converted to the format R, rounded to nearest and saturating. */
template<typename R, typename A>
requires(IsFixed<R>::value &&IsFixed<A>::value) constexpr R fixedCast(A a)
{
	using W = std::conditional_t<A::kSigned || R::kSigned, std::int64_t, std::uint64_t>;
	constexpr int shift = A::kFracBits - R::kFracBits;
	const W v = static_cast<W>(a.raw());
	if constexpr (shift > 0) {
		const W r = fixed_detail::shiftRound(v, shift);
		if constexpr (A::kSigned && !R::kSigned) {
			if (r < 0)
				return R::fromRaw(0);
		}
		return R::fromWideRaw(static_cast<typename R::wide>(r));
	} else {
		/* |raw| < 2^32 and shift >= -31: exact in 64 bits. */
		const W r = v * (W{ 1 } << (-shift));
		if constexpr (A::kSigned && !R::kSigned) {
			if (r < 0)
				return R::fromRaw(0);
		}
		return R::fromWideRaw(static_cast<typename R::wide>(r));
	}
}

/* Unsigned formats. */
using UQ8_8 = Fixed<8, 8, std::uint16_t>;
using UQ16_16 = Fixed<16, 16, std::uint32_t>;
using UQ24_8 = Fixed<24, 8, std::uint32_t>;
using UQ4_12 = Fixed<4, 12, std::uint16_t>;
/* Signed formats (the sign bit counts as an integer bit). */
using Q8_8 = Fixed<8, 8, std::int16_t>;
using Q16_16 = Fixed<16, 16, std::int32_t>;
using Q24_8 = Fixed<24, 8, std::int32_t>;

} /* namespace dockpose */
