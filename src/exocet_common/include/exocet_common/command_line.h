/**
 * @file command_line.h
 * @brief What every command-line tool and benchmark of the workspace does with its arguments, over CLI11: `--help`
 * prints the options on stdout and exits 0; a bad argument (unknown option, missing or malformed value, value out of
 * range, file that does not exist) prints CLI11's message, which names the option and the value, on stderr and exits
 * 2. Also the options that `make bench` gives every benchmark. No ROS in it.
 */
#pragma once

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>

namespace exocet_common {

/// Exit status of a tool given bad arguments or bad input (0: done; 1: an I/O or unexpected failure).
constexpr int kExitBadInput = 2;

/**
 * @brief Parses the command line into `app`'s options.
 * @return std::nullopt when the tool should go on; otherwise the status to exit with: 0 after `--help`, kExitBadInput
 * after a parse error. CLI11's own exit codes (105, 106, ...) are not used: scripts rely on 2 for bad input.
 */
inline std::optional<int> parseCommandLine(CLI::App& app, int argc, const char* const* argv) {
  try {
    app.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::CallForHelp&) {
    std::cout << app.help();
    return 0;
  } catch (const CLI::CallForAllHelp&) {
    std::cout << app.help("", CLI::AppFormatMode::All);
    return 0;
  } catch (const CLI::ParseError& e) {
    std::cerr << app.get_name() << ": " << e.what() << "\nRun '" << app.get_name() << " --help' for the options.\n";
    return kExitBadInput;
  }
}

/**
 * @brief Checks that an option's value is a number in an interval whose ends may be open or infinite, and says so in
 * the help ("(1, 179)", "[1, inf)"). CLI11's Range has closed ends only and, for a lower bound alone, prints the
 * largest double as the upper one.
 */
inline CLI::Validator numberIn(double low, bool low_open, double high, bool high_open) {
  const auto text = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  const std::string description = std::string(low_open ? "(" : "[") + text(low) + ", " +
                                  (std::isinf(high) ? std::string("inf") : text(high)) + (high_open ? ")" : "]");
  return CLI::Validator(
      [=](std::string& input) {
        char* end = nullptr;
        const double v = std::strtod(input.c_str(), &end);
        if (input.empty() || *end != '\0' || std::isnan(v)) return "'" + input + "' is not a number";
        const bool above = low_open ? v > low : v >= low;
        const bool below = high_open ? v < high : v <= high;
        return above && below ? std::string() : input + " is not in " + description;
      },
      description);
}

/// A number >= `minimum`.
inline CLI::Validator atLeast(double minimum) {
  return numberIn(minimum, false, std::numeric_limits<double>::infinity(), true);
}

/// A number > `minimum`.
inline CLI::Validator greaterThan(double minimum) {
  return numberIn(minimum, true, std::numeric_limits<double>::infinity(), true);
}

/// Where a benchmark writes its figures and reads the shared data sets (tools/run-bench.sh gives both to every one).
struct BenchmarkPaths {
  std::string output_dir = "out/bench";
  std::string shared_data = "../shared/data";
};

/**
 * @brief Adds `--output-dir DIR` and `--shared-data DIR` to a benchmark's options.
 * @param paths their defaults on entry, the values given after parsing
 * @param uses_shared_data false for a benchmark that reads no shared data: the option is accepted, so that every
 * benchmark takes the same command line, and ignored
 */
inline void addBenchmarkPathOptions(CLI::App& app, BenchmarkPaths* paths, bool uses_shared_data = true) {
  app.add_option("--output-dir", paths->output_dir, "folder of the JSON figures (and of any cache)")
      ->type_name("DIR")
      ->capture_default_str();
  if (uses_shared_data) {
    app.add_option("--shared-data", paths->shared_data, "folder of the shared data sets (../shared/data)")
        ->type_name("DIR")
        ->capture_default_str();
  } else {
    app.add_option("--shared-data", paths->shared_data, "ignored: this benchmark reads no shared data")
        ->type_name("DIR");
  }
}

}  // namespace exocet_common
