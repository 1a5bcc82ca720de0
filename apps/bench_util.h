// Timing and statistics shared by the benchmarks (apps/bench_*.cc).
#pragma once

#include <vector>

namespace arreg::cli {

// CPU time of the calling thread in ms: robust to other processes sharing the machine.
double ThreadCpuMs();
// Monotonic wall-clock time in ms (steady_clock; for differences only).
double WallMs();
// Median of a sample (mean of the two middle values for an even count); 0 when empty.
double Median(std::vector<double> values);
// Least-squares slope k of log(cost) over log(size), cost ~ size^k (1 = linear growth).
// Needs two or more distinct positive sizes and positive costs of the same count.
double GrowthExponent(const std::vector<double>& sizes, const std::vector<double>& costs);

}  // namespace arreg::cli
