// The rim subcommands: each file adds one to the application.
#pragma once

#include <CLI/CLI.hpp>

namespace range_image_mapping::tool {

void addDecodeCommand(CLI::App& app);
void addEvalCommand(CLI::App& app);
void addMapCommand(CLI::App& app);
void addOdometryCommand(CLI::App& app);
void addSimulateCommand(CLI::App& app);

}  // namespace range_image_mapping::tool
