#include "command_line.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>

namespace range_image_mapping::tool {

namespace po = boost::program_options;

namespace {

// Positionals past the declared ones land here, to be named in the error.
const char* const kExtraArguments = "extra arguments";

bool readNumber(const std::string& text, double& number) {
  char* end = nullptr;
  number = std::strtod(text.c_str(), &end);
  return !text.empty() && end == text.c_str() + text.size();
}

std::string numberText(double number) {
  std::ostringstream stream;
  stream << std::setprecision(12) << number;
  return stream.str();
}

bool isHelp(const std::string& argument) { return argument == "-h" || argument == "--help"; }

// "-1", "-0.5", "-.5": a value, not an option.
bool looksNegative(const std::string& argument) {
  double number;
  return argument.size() > 1 && argument[0] == '-' && readNumber(argument, number);
}

// Words wrapped at width, every line after the first indented.
std::string wrap(const std::string& text, std::size_t indent, std::size_t width) {
  std::istringstream words(text);
  std::string result, word;
  std::size_t column = indent;
  while (words >> word) {
    if (column > indent && column + 1 + word.size() > width) {
      result += "\n" + std::string(indent, ' ');
      column = indent;
    } else if (column > indent) {
      result += ' ';
      ++column;
    }
    result += word;
    column += word.size();
  }
  return result;
}

// One row of --help: the left column, then the text wrapped beside it.
void printRow(const std::string& left, const std::string& text) {
  constexpr std::size_t kColumn = 32, kWidth = 100;
  std::cout << "  " << left;
  if (left.size() + 2 >= kColumn)
    std::cout << "\n" << std::string(kColumn, ' ');
  else
    std::cout << std::string(kColumn - 2 - left.size(), ' ');
  std::cout << wrap(text, kColumn, kWidth) << "\n";
}

}  // namespace

// ---------------------------------------------------------------- checks

Check inRange(double low, double high) {
  return {"[" + numberText(low) + " - " + numberText(high) + "]", [low, high](const std::string& text) {
            double value;
            if (readNumber(text, value) && value >= low && value <= high) return std::string();
            return "Value " + text + " not in range " + numberText(low) + " to " + numberText(high);
          }};
}

Check positive() {
  return {"POSITIVE", [](const std::string& text) {
            double value;
            return readNumber(text, value) && value > 0 ? std::string() : "Value " + text + " is not positive";
          }};
}

Check nonNegative() {
  return {"NONNEGATIVE", [](const std::string& text) {
            double value;
            return readNumber(text, value) && value >= 0 ? std::string() : "Value " + text + " is negative";
          }};
}

Check oneOf(const std::vector<std::string>& choices) {
  std::string set;
  for (const std::string& choice : choices) set += (set.empty() ? "" : ",") + choice;
  set = "{" + set + "}";
  return {set, [choices, set](const std::string& text) {
            return std::find(choices.begin(), choices.end(), text) != choices.end() ? std::string()
                                                                                    : text + " not in " + set;
          }};
}

Check existingFile() {
  return {"FILE", [](const std::string& text) {
            std::error_code error;
            const std::filesystem::file_status status = std::filesystem::status(text, error);
            if (!std::filesystem::exists(status)) return "File does not exist: " + text;
            if (std::filesystem::is_directory(status)) return "File is actually a directory: " + text;
            return std::string();
          }};
}

// ---------------------------------------------------------------- options

Option& Option::required() {
  is_required = true;
  return *this;
}

Option& Option::check(Check check) {
  checks.push_back(std::move(check));
  return *this;
}

Option& Option::showDefault() {
  show_default = true;
  return *this;
}

Option& Option::excludes(const std::string& other) {
  Option* excluded_option = owner->find(other);
  if (!excluded_option) throw std::logic_error("rim: " + displayName() + " excludes an undeclared " + other);
  excluded.push_back(excluded_option->displayName());
  excluded_option->excluded.push_back(displayName());
  return *this;
}

std::string Option::displayName() const {
  if (positional) return long_name;
  return long_name.empty() ? "-" + short_name : "--" + long_name;
}

namespace command_line_detail {

std::vector<std::string> listItems(const std::vector<std::string>& words) {
  std::vector<std::string> items;
  for (const std::string& word : words) {
    std::istringstream stream(word);
    for (std::string item; std::getline(stream, item, ',');)
      if (!item.empty()) items.push_back(item);
  }
  return items;
}

void throwConversionError(const std::string& option, const std::string& value) {
  throw UsageError("the argument ('" + value + "') for option '" + option + "' is invalid", UsageExit::kConversion);
}

}  // namespace command_line_detail

// ---------------------------------------------------------------- commands

Command::Command(std::string name, std::string description, std::string path)
    : name_(std::move(name)), description_(std::move(description)), path_(path.empty() ? name_ : std::move(path)) {}

Command& Command::subcommand(const std::string& name, const std::string& description) {
  subcommands_.push_back(std::make_unique<Command>(name, description, path_ + " " + name));
  return *subcommands_.back();
}

Option& Command::add(const std::string& names, const std::string& help, const std::string& type_name,
                     const std::string& value_text, po::value_semantic* semantic) {
  auto option = std::make_unique<Option>();
  std::istringstream stream(names);
  for (std::string name; std::getline(stream, name, ',');) {
    if (name.rfind("--", 0) == 0)
      option->long_name = name.substr(2);
    else if (name.rfind('-', 0) == 0)
      option->short_name = name.substr(1);
    else
      option->long_name = name, option->positional = true;
  }
  option->owner = this;
  option->help = help;
  option->type_name = type_name;
  option->value_text = value_text;
  const bool both = !option->long_name.empty() && !option->short_name.empty();
  described_.add_options()((option->key() + (both ? "," + option->short_name : "")).c_str(), semantic, help.c_str());
  if (option->positional) positionals_.add(option->long_name.c_str(), 1);
  options_.push_back(std::move(option));
  return *options_.back();
}

Option& Command::flag(const std::string& names, bool& value, const std::string& help) {
  Option& option = add(names, help, "", "", po::value<bool>(&value)->zero_tokens());
  option.flag = true;
  return option;
}

Option* Command::find(const std::string& name) {
  for (const auto& option : options_)
    if (name == option->key() || name == option->displayName() ||
        (!option->short_name.empty() && name == "-" + option->short_name))
      return option.get();
  return nullptr;
}

bool Command::given(const std::string& name) const {
  for (const auto& option : options_)
    if (option->displayName() == name) return given_.count(option->key()) > 0;
  throw std::logic_error("rim: no option " + name + " in " + path_);
}

int Command::main(int argc, char** argv) {
  try {
    run(std::vector<std::string>(argv + 1, argv + argc));
  } catch (const UsageError& error) {
    std::cerr << error.what() << "\nRun with --help for more information.\n";
    return error.exit_code;
  } catch (const CommandFailed& error) {
    std::cerr << name_ << ": " << error.what() << "\n";
    return error.exit_code;
  } catch (const std::exception& error) {
    std::cerr << name_ << ": error: " << error.what() << "\n";
    return 1;
  }
  return 0;
}

void Command::run(const std::vector<std::string>& arguments) {
  if (!subcommands_.empty()) {
    if (arguments.empty()) throw UsageError("A subcommand is required", UsageExit::kRequired);
    for (const auto& command : subcommands_)
      if (command->name_ == arguments.front())
        return command->run(std::vector<std::string>(arguments.begin() + 1, arguments.end()));
    if (isHelp(arguments.front())) return printHelp();
    std::string names;
    for (const auto& command : subcommands_) names += (names.empty() ? "" : ", ") + command->name_;
    throw UsageError("A subcommand is required: one of " + names + ", not " + arguments.front(),
                     UsageExit::kRequired);
  }
  for (const std::string& argument : arguments) {
    if (argument == "--") break;
    if (isHelp(argument)) return printHelp();
  }
  parse(arguments);
  if (callback_) callback_();
}

void Command::parse(std::vector<std::string> arguments) {
  for (std::size_t i = 0; i < arguments.size() && arguments[i] != "--"; ++i) {
    if (arguments[i].rfind("--", 0) != 0) continue;
    const std::size_t equals = arguments[i].find('=');
    const Option* option = find(arguments[i].substr(0, equals));
    if (!option || option->positional) continue;
    if (option->flag && equals != std::string::npos) {
      // "--flag=true" is "--flag", "--flag=false" is no flag.
      const std::string value = arguments[i].substr(equals + 1);
      if (value == "false" || value == "0" || value == "off" || value == "no") {
        arguments.erase(arguments.begin() + std::ptrdiff_t(i--));
      } else if (value == "true" || value == "1" || value == "on" || value == "yes") {
        arguments[i].resize(equals);
      }
    } else if (!option->flag && equals == std::string::npos && i + 1 < arguments.size() &&
               looksNegative(arguments[i + 1])) {
      // A negative number after an option that takes a value is that value
      // (Program_options would take it for an option).
      arguments[i] += "=" + arguments[i + 1];
      arguments.erase(arguments.begin() + std::ptrdiff_t(i) + 1);
    }
  }

  po::options_description everything;
  everything.add(described_);
  everything.add_options()(kExtraArguments, po::value<std::vector<std::string>>());
  po::positional_options_description positionals = positionals_;
  positionals.add(kExtraArguments, -1);
  po::parsed_options parsed(&everything);
  try {
    parsed = po::command_line_parser(arguments)
                 .options(everything)
                 .positional(positionals)
                 .style(po::command_line_style::default_style & ~po::command_line_style::allow_guessing)
                 .run();
  } catch (const po::unknown_option& error) {
    throw UsageError("The following argument was not expected: " + error.get_option_name(), UsageExit::kExtras);
  } catch (const po::error& error) {
    throw UsageError(error.what(), UsageExit::kSyntax);
  }

  // Positionals only by position, and no more than declared.
  std::vector<std::string> extras;
  for (const po::option& given : parsed.options) {
    const Option* option = given.string_key == kExtraArguments ? nullptr : find(given.string_key);
    if (given.position_key < 0 && (!option || option->positional))
      extras.push_back(given.original_tokens.front());
    else if (!option)
      extras.insert(extras.end(), given.value.begin(), given.value.end());
  }
  if (!extras.empty()) {
    std::string words;
    for (const std::string& word : extras) words += (words.empty() ? "" : " ") + word;
    throw UsageError(std::string("The following argument") + (extras.size() > 1 ? "s were" : " was") +
                         " not expected: " + words,
                     UsageExit::kExtras);
  }
  // Checks on the text.
  for (const po::option& given : parsed.options) {
    Option* option = find(given.string_key);
    if (!option) continue;
    const std::vector<std::string> texts = option->list ? command_line_detail::listItems(given.value) : given.value;
    for (const Check& check : option->checks)
      for (const std::string& text : texts)
        if (const std::string error = check.error(text); !error.empty())
          throw UsageError(option->displayName() + ": " + error, UsageExit::kValidation);
  }

  po::variables_map values;
  try {
    po::store(parsed, values);
  } catch (const po::validation_error& error) {
    throw UsageError(error.what(), UsageExit::kConversion);
  } catch (const po::error& error) {
    throw UsageError(error.what(), UsageExit::kSyntax);
  }
  given_ = values;
  for (const bool positional : {true, false})  // positionals first, as they come first
    for (const auto& option : options_)
      if (option->positional == positional && option->is_required && !given(option->displayName()))
        throw UsageError(option->displayName() + " is required", UsageExit::kRequired);
  for (const auto& option : options_) {
    if (given(option->displayName()))
      for (const std::string& other : option->excluded)
        if (given(other)) throw UsageError(option->displayName() + " excludes " + other, UsageExit::kExcludes);
  }
  po::notify(values);  // into the variables
}

void Command::printHelp() const {
  std::cout << description_ << "\nUsage: " << path_ << " [OPTIONS]";
  if (!subcommands_.empty()) std::cout << " SUBCOMMAND";
  for (const auto& option : options_)
    if (option->positional) std::cout << " " << option->long_name;
  std::cout << "\n";

  const auto left = [](const Option& option) {
    std::string text = option.positional ? option.long_name
                       : option.short_name.empty()
                           ? "--" + option.long_name
                           : "-" + option.short_name + (option.long_name.empty() ? "" : ",--" + option.long_name);
    if (!option.flag) {
      text += " " + option.type_name;
      for (const Check& check : option.checks)
        if (!check.description.empty()) text += ":" + check.description;
    }
    if (option.show_default) text += "=" + option.value_text;
    if (option.is_required) text += " REQUIRED";
    for (const std::string& other : option.excluded) text += " Excludes: " + other;
    return text;
  };
  bool positionals = false;
  for (const auto& option : options_)
    if (option->positional) {
      if (!positionals) std::cout << "\nPositionals:\n";
      positionals = true;
      printRow(left(*option), option->help);
    }
  std::cout << "\nOptions:\n";
  printRow("-h,--help", "Print this help message and exit");
  for (const auto& option : options_)
    if (!option->positional) printRow(left(*option), option->help);
  if (!subcommands_.empty()) {
    std::cout << "\nSubcommands:\n";
    for (const auto& command : subcommands_) printRow(command->name_, command->description_);
  }
}

}  // namespace range_image_mapping::tool
