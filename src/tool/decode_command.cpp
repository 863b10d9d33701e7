// rim decode: Ouster pcap + metadata -> PLY point clouds and range image PNGs.
#include "commands.h"

namespace range_image_mapping::tool {

void addDecodeCommand(CLI::App& app) {
  app.add_subcommand("decode", "decode an Ouster pcap into PLY clouds and range image PNGs");
}

}  // namespace range_image_mapping::tool
