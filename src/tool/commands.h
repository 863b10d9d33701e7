// The rim subcommands: each file adds one to the application.
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

namespace range_image_mapping::tool {

void addDecodeCommand(CLI::App& app);
void addEvalCommand(CLI::App& app);
void addMapCommand(CLI::App& app);
void addOdometryCommand(CLI::App& app);
void addRunCommand(CLI::App& app);
void addSimulateCommand(CLI::App& app);

// rim simulate's ready-made sequences (outdoor_car, indoor_cart, ...), which
// rim run also takes as INPUT.
std::vector<std::string> simulationPresetNames();
bool isIndoorPreset(const std::string& preset);
// Writes the preset's sequence (its default formats, frames if > 0) into directory.
void simulatePreset(const std::string& preset, const std::string& directory, int frames);

}  // namespace range_image_mapping::tool
