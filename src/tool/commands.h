// The rim subcommands: each file adds one to the application.
#pragma once

#include "command_line.h"

#include <string>
#include <vector>

namespace range_image_mapping::tool {

void addDecodeCommand(Command& rim);
void addEvalCommand(Command& rim);
void addMapCommand(Command& rim);
void addOdometryCommand(Command& rim);
void addRunCommand(Command& rim);
void addSensorCommand(Command& rim);
void addSimulateCommand(Command& rim);

// rim simulate's ready-made sequences (outdoor_car, indoor_cart, ...), which
// rim run also takes as INPUT.
std::vector<std::string> simulationPresetNames();
bool isIndoorPreset(const std::string& preset);
// Writes the preset's sequence (its default formats, frames if > 0) into
// directory, plus extra_format if not empty (e.g. "bag"); its ground-truth
// surface holds what was seen within surface_max_range_m (0: all). Returns the
// recording to read: directory, or its clouds/ for a sensor without packets.
std::string simulatePreset(const std::string& preset, const std::string& directory, int frames,
                    double surface_max_range_m, const std::string& extra_format = "");

}  // namespace range_image_mapping::tool
