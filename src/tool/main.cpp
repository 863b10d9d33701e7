// rim: the range_image_mapping command-line tool.
#include "commands.h"

int main(int argc, char** argv) {
  range_image_mapping::tool::Command rim("rim", "rim: LiDAR range-image odometry and mapping tools");
  range_image_mapping::tool::addDecodeCommand(rim);
  range_image_mapping::tool::addSimulateCommand(rim);
  range_image_mapping::tool::addEvalCommand(rim);
  range_image_mapping::tool::addOdometryCommand(rim);
  range_image_mapping::tool::addMapCommand(rim);
  range_image_mapping::tool::addRunCommand(rim);
  range_image_mapping::tool::addSensorCommand(rim);
  return rim.main(argc, argv);
}
