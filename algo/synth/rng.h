/* SPDX-License-Identifier: MIT */
/*
 * The synthetic frames' random streams (renderer and evaluation): mt19937_64
 * with our own transforms, so a seed gives the same frame with every standard
 * library (std::uniform_real_distribution and std::normal_distribution are not
 * specified bit for bit). Test and tool code; allocates never.
 */
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>

namespace dockpose::synth {

/* A 64-bit mix (splitmix64's finaliser): derives independent seeds from one. */
inline std::uint64_t splitmix64(std::uint64_t x)
{
	x += 0x9e3779b97f4a7c15ULL;
	x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
	x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
	return x ^ (x >> 31);
}

class Rng
{
public:
	explicit Rng(std::uint64_t seed)
		: engine_(seed)
	{
	}

	/* Uniform in [0, 1) with 53 bits. */
	double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
	double uniform(double a, double b) { return a + (b - a) * uniform(); }
	/* Uniform integer in [0, n), n > 0. */
	int index(int n) { return std::min(n - 1, static_cast<int>(uniform() * n)); }
	bool chance(double p) { return uniform() < p; }
	/* Standard normal (Box-Muller on two uniforms; the second value is not kept). */
	double normal()
	{
		const double u1 = 1.0 - uniform(); /* (0, 1]: log() finite */
		const double u2 = uniform();
		return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * 3.14159265358979323846 * u2);
	}
	std::uint64_t next() { return engine_(); }

private:
	std::mt19937_64 engine_;
};

} /* namespace dockpose::synth */
