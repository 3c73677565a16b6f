/* SPDX-License-Identifier: MIT */
/*
 * The benchmarks' console reporter that also keeps each benchmark's median
 * (real time, in the benchmark's unit; manual time where the benchmark sets
 * it), its CPU time and its user counters by function name, so that main()
 * can print the ratios of one run. Allocates: per run reported (not timed).
 */
#pragma once

#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

namespace dockpose::bench {

class RatioReporter : public benchmark::ConsoleReporter
{
public:
	void ReportRuns(const std::vector<Run> &runs) override
	{
		ConsoleReporter::ReportRuns(runs);
		for (const Run &run : runs)
			if (run.run_type == Run::RT_Aggregate && run.aggregate_name == "median") {
				median_us[run.run_name.function_name] = run.GetAdjustedRealTime();
				median_cpu_us[run.run_name.function_name] =
					run.GetAdjustedCPUTime();
				for (const auto &[name, counter] : run.counters)
					median_counter[run.run_name.function_name][name] =
						counter.value;
			}
	}
	std::map<std::string, double> median_us;
	/* The benchmark thread's CPU time (other threads, e.g. a worker, not included). */
	std::map<std::string, double> median_cpu_us;
	/* The medians of the user counters, by function name, then counter name. */
	std::map<std::string, std::map<std::string, double>> median_counter;
};

} /* namespace dockpose::bench */
