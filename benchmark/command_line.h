// The benchmarks' command lines: options with values, and comma-separated lists.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::benchmark_support {

// A comma-separated command-line value ("a,b,c") as its items, empty items dropped.
inline std::vector<std::string> splitList(const std::string& text) {
  std::vector<std::string> items;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');)
    if (!item.empty()) items.push_back(item);
  return items;
}

// Walks argv one option at a time; value() takes the argument after the option, and names the option
// when there is none.
class ArgumentCursor {
 public:
  ArgumentCursor(int argc, char** argv) : argc_(argc), argv_(argv) {}

  bool next() {
    if (++index_ >= argc_) return false;
    name_ = argv_[index_];
    return true;
  }
  const std::string& name() const { return name_; }
  std::string value() {
    if (index_ + 1 >= argc_) throw std::invalid_argument(name_ + " needs a value");
    return argv_[++index_];
  }
  int integer() {
    return parsed<int>([](const std::string& text, std::size_t* end) { return std::stoi(text, end); }, "an integer");
  }
  double number() {
    return parsed<double>([](const std::string& text, std::size_t* end) { return std::stod(text, end); }, "a number");
  }

 private:
  int argc_;
  char** argv_;
  int index_ = 0;
  std::string name_;

  // The whole value must parse: "10x" is an error, not 10.
  template <typename T, typename Parse>
  T parsed(Parse parse, const char* kind) {
    const std::string text = value();
    std::size_t end = 0;
    T result{};
    try {
      result = parse(text, &end);
    } catch (const std::exception&) {
      end = 0;
    }
    if (end == 0 || end != text.size()) throw std::invalid_argument(name_ + ": '" + text + "' is not " + kind);
    return result;
  }
};

}  // namespace range_image_mapping::benchmark_support
