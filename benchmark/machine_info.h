// What every benchmark prints about the machine it ran on (the CPU, the load
// of a machine shared with other jobs, the date) and the process CPU time,
// shared so that the benchmarks' headers read alike.
#pragma once

#include <cstdio>
#include <ctime>
#include <exception>
#include <fstream>
#include <string>

namespace range_image_mapping::benchmark_support {

// CPU seconds of the whole process (all threads): on a shared machine the wall
// time depends on the load, the CPU time much less.
inline double processCpuSeconds() {
  timespec time{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &time);
  return double(time.tv_sec) + 1e-9 * double(time.tv_nsec);
}

inline std::string cpuModel() {
  std::ifstream file("/proc/cpuinfo");
  for (std::string line; std::getline(file, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown CPU";
}

inline std::string loadAverage() {
  std::ifstream file("/proc/loadavg");
  std::string one, five, fifteen;
  file >> one >> five >> fifteen;
  return one + " " + five + " " + fifteen;
}

inline std::string now() {
  const std::time_t time = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M", std::localtime(&time));
  return text;
}

// A benchmark's main(): runs it, and turns an exception (bad input, missing
// data) into a message naming the program and exit status 1.
template <typename Run>
int runReportingErrors(const char* program, Run run, int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "%s: %s\n", program, error.what());
    return 1;
  }
}

}  // namespace range_image_mapping::benchmark_support
