// rim: the range_image_mapping command-line tool.
#include "commands.h"

#include <exception>
#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{"rim: LiDAR range-image odometry and mapping tools"};
  app.require_subcommand(1);
  range_image_mapping::tool::addDecodeCommand(app);
  range_image_mapping::tool::addSimulateCommand(app);
  range_image_mapping::tool::addEvalCommand(app);
  range_image_mapping::tool::addOdometryCommand(app);
  range_image_mapping::tool::addMapCommand(app);
  range_image_mapping::tool::addRunCommand(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::RuntimeError& error) {  // a command that ran and failed
    std::cerr << "rim: " << error.what() << "\n";
    return error.get_exit_code();
  } catch (const CLI::ParseError& error) {
    return app.exit(error);
  } catch (const std::exception& error) {
    std::cerr << "rim: error: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
