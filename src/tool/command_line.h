// rim's command line on Boost.Program_options: a tree of commands (rim, rim
// eval, rim eval mesh, ...), each with options, positionals and flags bound to
// variables, checks on their text (range, choice, existing file), required
// options and exclusions, --help generated from the same declarations, and
// the exit codes of a mistake. Each subcommand file only declares.
#pragma once

#include <boost/lexical_cast.hpp>
#include <boost/program_options.hpp>

#include <functional>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace range_image_mapping::tool {

// Exit codes of command-line mistakes (the numbers rim has always used).
enum class UsageExit : int {
  kConversion = 104,  // a value that is not of the option's type
  kValidation = 105,  // a value a check refused
  kRequired = 106,    // a required option, positional or subcommand is missing
  kExcludes = 108,    // two options that exclude each other
  kExtras = 109,      // an unknown option or an argument too many
  kSyntax = 114,      // an option without its value, or given twice
};

// A command-line mistake: printed with "Run with --help for more information."
// Commands throw it too, for mistakes only seen once all options are known.
class UsageError : public std::runtime_error {
 public:
  explicit UsageError(const std::string& message, UsageExit exit = UsageExit::kValidation)
      : std::runtime_error(message), exit_code(static_cast<int>(exit)) {}
  int exit_code;
};

// A command that ran and failed with an exit status of its own (printed as "rim: <message>").
class CommandFailed : public std::runtime_error {
 public:
  CommandFailed(const std::string& message, int exit_status) : std::runtime_error(message), exit_code(exit_status) {}
  int exit_code;
};

// A check of an option's text: its error ("" when the text passes) and what
// --help shows after the type (e.g. "POSITIVE", "{lidar,sensor}").
struct Check {
  std::string description;
  std::function<std::string(const std::string& text)> error;
};
Check inRange(double low, double high);
Check positive();
Check nonNegative();
Check oneOf(const std::vector<std::string>& choices);
Check existingFile();

class Command;

// One option as declared; Command::option returns it to add requirements.
class Option {
 public:
  Option& required();
  Option& check(Check check);
  Option& showDefault();  // show the variable's value at declaration in --help
  Option& excludes(const std::string& other);  // both ways; other (e.g. "--voxel") declared before

 private:
  friend class Command;
  Command* owner = nullptr;
  std::string long_name, short_name;  // without dashes; long_name is the positional's name
  bool positional = false, flag = false, list = false, is_required = false;
  std::string help, type_name, value_text;
  bool show_default = false;
  std::vector<Check> checks;
  std::vector<std::string> excluded;
  std::string key() const { return long_name.empty() ? short_name : long_name; }  // Program_options' name
  std::string displayName() const;
};

class Command {
 public:
  Command(std::string name, std::string description, std::string path = "");
  Command(const Command&) = delete;
  friend class Option;
  Command& operator=(const Command&) = delete;

  Command& subcommand(const std::string& name, const std::string& description);

  // names: "--out,-o" for an option, "input" for a positional (in order of declaration).
  template <typename T>
  Option& option(const std::string& names, T& value, const std::string& help);
  // A list, comma-separated and/or in several words ("--rpe-lengths 100,200").
  template <typename T>
  Option& option(const std::string& names, std::vector<T>& values, const std::string& help);
  Option& flag(const std::string& names, bool& value, const std::string& help);

  // What the command does once its command line is read.
  void callback(std::function<void()> run) { callback_ = std::move(run); }
  // Whether the last command line gave this option ("--voxel").
  bool given(const std::string& name) const;

  // Reads the command line (argv[1..]) down the command tree, runs the chosen
  // command, prints errors and returns the exit status.
  int main(int argc, char** argv);

 private:
  Option& add(const std::string& names, const std::string& help, const std::string& type_name,
              const std::string& value_text, boost::program_options::value_semantic* semantic);
  Option* find(const std::string& name);  // "--out", "-o", or its key
  void run(const std::vector<std::string>& arguments);
  void parse(std::vector<std::string> arguments);
  void printHelp() const;

  std::string name_, description_, path_;
  std::vector<std::unique_ptr<Command>> subcommands_;
  std::vector<std::unique_ptr<Option>> options_;
  boost::program_options::options_description described_;
  boost::program_options::positional_options_description positionals_;
  boost::program_options::variables_map given_;
  std::vector<std::string> extra_arguments_;  // positionals past the declared ones
  std::function<void()> callback_;
};

// ---------------------------------------------------------------- details

namespace command_line_detail {
template <typename T>
std::string typeName() {
  if constexpr (std::is_same_v<T, std::string>) return "TEXT";
  else if constexpr (std::is_floating_point_v<T>) return "FLOAT";
  else if constexpr (std::is_unsigned_v<T>) return "UINT";
  else return "INT";
}
template <typename T>
std::string text(const T& value) {
  if constexpr (std::is_same_v<T, std::string>) return value;
  else {
    std::ostringstream stream;
    stream << value;
    return stream.str();
  }
}
// The pieces of a list's words split at commas.
std::vector<std::string> listItems(const std::vector<std::string>& words);
[[noreturn]] void throwConversionError(const std::string& option, const std::string& value);
}  // namespace command_line_detail

template <typename T>
Option& Command::option(const std::string& names, T& value, const std::string& help) {
  Option& option = add(names, help, command_line_detail::typeName<T>(), command_line_detail::text(value),
                       boost::program_options::value<T>(&value));
  // Conversion would wrap "-1" round; the check is implied by the type, not shown.
  if constexpr (std::is_unsigned_v<T>) option.check({"", nonNegative().error});
  return option;
}

template <typename T>
Option& Command::option(const std::string& names, std::vector<T>& values, const std::string& help) {
  std::string shown;
  for (const T& value : values) shown += (shown.empty() ? "" : ",") + command_line_detail::text(value);
  const std::string display = names.substr(0, names.find(','));
  auto* semantic = boost::program_options::value<std::vector<std::string>>()->multitoken()->notifier(
      [&values, display](const std::vector<std::string>& words) {
        values.clear();
        for (const std::string& item : command_line_detail::listItems(words)) {
          try {
            values.push_back(boost::lexical_cast<T>(item));
          } catch (const boost::bad_lexical_cast&) {
            command_line_detail::throwConversionError(display, item);
          }
        }
      });
  Option& option = add(names, help, command_line_detail::typeName<T>() + " ...", shown, semantic);
  option.list = true;
  return option;
}

}  // namespace range_image_mapping::tool
