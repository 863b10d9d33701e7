// Zero copy between nodelets. This process loads the Adapter, the Odometry
// and the Mapper with nodelet::Loader, as a nodelet manager does, while
// rosbag play replays a simulated sequence into them; two subscribers here
// take range_image as boost::shared_ptr<const LidarRangeImage>.
//
// What roscpp does (checked by the first test, on a topic of its own): a
// message published as a shared_ptr reaches every subscriber of the same C++
// type in the process as that very pointer, never serialized; a message
// published by value is serialized and deserialized into a new object (one
// per process and type, shared by those subscribers, so equal addresses at
// two subscribers prove nothing by themselves). The new object comes from
// the message factory of the first subscriber of that type: here the test's
// subscribers, subscribed before the nodelets load, whose factory records
// every object it makes. A received message the factory did not make was
// never deserialized: it is the object the publisher published.
//
// The Adapter's images (second test): both subscribers must get the same
// object, never one the factory made; the Odometry and the Mapper must have
// used them; and no message may change after its publication: every pointer
// is kept and the content hashed on receipt and again at the end.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/SaveMesh.h"

#include "rostest_main.h"
#include "spin_until.h"

#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <nodelet/loader.h>
#include <ros/ros.h>
#include <ros/serialization.h>

#include <boost/make_shared.hpp>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <map>
#include <mutex>
#include <regex>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;
using ImagePtr = LidarRangeImage::ConstPtr;

// FNV-1a over the serialized message: every field, in wire order.
uint64_t contentHash(const LidarRangeImage& message) {
  const ros::SerializedMessage bytes = ros::serialization::serializeMessage(message);
  uint64_t hash = 14695981039346656037ull;
  for (std::size_t i = 0; i < bytes.num_bytes; ++i) {
    hash ^= bytes.buf[i];
    hash *= 1099511628211ull;
  }
  return hash;
}

// Every message roscpp deserializes for the test's subscribers, kept alive so
// no later message can reuse an address.
class MessageFactory {
 public:
  boost::shared_ptr<LidarRangeImage> make() {
    const auto message = boost::make_shared<LidarRangeImage>();
    std::lock_guard<std::mutex> lock(mutex_);
    made_.push_back(message);
    return message;
  }
  bool made(const LidarRangeImage* message) const {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& mine : made_)
      if (mine.get() == message) return true;
    return false;
  }
  std::size_t count() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return made_.size();
  }

 private:
  mutable std::mutex mutex_;
  std::vector<boost::shared_ptr<LidarRangeImage>> made_;
};

// One subscriber's view: every message kept, with its hash on receipt.
struct ImageSubscriber {
  std::vector<ImagePtr> messages;
  std::vector<uint64_t> hashes;
  ros::Subscriber subscriber;

  void subscribe(ros::NodeHandle& node, const std::string& topic, MessageFactory& factory) {
    ros::SubscribeOptions options;
    options.init<LidarRangeImage>(
        topic, 100,
        [this](const ImagePtr& message) {
          messages.push_back(message);
          hashes.push_back(contentHash(*message));
        },
        [&factory] { return factory.make(); });
    subscriber = node.subscribe(options);
  }
};

boost::shared_ptr<LidarRangeImage> smallImage() {
  const auto image = boost::make_shared<LidarRangeImage>();
  image->header.frame_id = "os_lidar";
  image->height = 2;
  image->width = 3;
  image->range = {1.0f, 2.0f, NAN, 4.0f, 5.0f, 6.0f};
  image->column_timestamps = {10, 20, 30};
  image->sensor_model = "control";
  return image;
}

TEST(ZeroCopy, RoscppHandsSharedPointersOverAndDeserializesByValuePublishes) {
  ros::NodeHandle node;
  ros::Publisher publisher = node.advertise<LidarRangeImage>("/zero_copy_control", 4);
  MessageFactory factory;
  ImageSubscriber first, second;
  first.subscribe(node, "/zero_copy_control", factory);
  second.subscribe(node, "/zero_copy_control", factory);
  ASSERT_TRUE(spinUntil([&] { return publisher.getNumSubscribers() > 0; }, 10.0)) << "no intra-process subscriber";

  const boost::shared_ptr<LidarRangeImage> published = smallImage();
  publisher.publish(boost::shared_ptr<const LidarRangeImage>(published));
  ASSERT_TRUE(spinUntil([&] { return first.messages.size() == 1 && second.messages.size() == 1; }, 10.0));
  EXPECT_EQ(first.messages[0].get(), published.get()) << "a shared_ptr publish reached the subscriber as a copy";
  EXPECT_EQ(second.messages[0].get(), published.get()) << "a shared_ptr publish reached the subscriber as a copy";
  EXPECT_EQ(factory.count(), 0u) << "a shared_ptr publish was deserialized";

  publisher.publish(*published);  // by value: serialized
  ASSERT_TRUE(spinUntil([&] { return first.messages.size() == 2 && second.messages.size() == 2; }, 10.0));
  EXPECT_NE(first.messages[1].get(), published.get()) << "a by-value publish reached the subscriber uncopied";
  EXPECT_NE(second.messages[1].get(), published.get()) << "a by-value publish reached the subscriber uncopied";
  EXPECT_TRUE(factory.made(first.messages[1].get())) << "the copy did not come from the subscriber's factory";
  EXPECT_TRUE(factory.made(second.messages[1].get())) << "the copy did not come from the subscriber's factory";
  EXPECT_EQ(first.hashes[1], contentHash(*published)) << "the deserialized copy differs from the original";
  std::cout << "by-value publish: the two subscribers got " << (first.messages[1] == second.messages[1] ? "one" : "two")
            << " deserialized cop" << (first.messages[1] == second.messages[1] ? "y" : "ies")
            << ", never the published object\n";
}

TEST(ZeroCopy, NodeletsShareTheAdaptersImagesAndNothingChangesThem) {
  ros::NodeHandle private_node("~");
  const std::string sequence_dir = private_node.param<std::string>("sequence_dir", "");
  const int min_images = private_node.param("min_images", 8);
  const double timeout_s = private_node.param("timeout", 80.0);
  ASSERT_TRUE(std::filesystem::exists(sequence_dir + "/packets.bag")) << sequence_dir;

  ros::NodeHandle node;
  // Subscribed before the nodelets load: any deserialization uses this factory.
  MessageFactory factory;
  ImageSubscriber first, second;
  first.subscribe(node, "/range_image", factory);
  second.subscribe(node, "/range_image", factory);
  std::vector<nav_msgs::Odometry::ConstPtr> odometry;
  ros::Subscriber odometry_subscriber = node.subscribe<nav_msgs::Odometry>(
      "/odometry", 100, [&](const nav_msgs::Odometry::ConstPtr& message) { odometry.push_back(message); });

  // As a nodelet manager would, with the remappings of range_image_mapping.launch.
  nodelet::Loader loader(false);
  const nodelet::M_string packets_remapping{{"/lidar_packets", "/ouster/lidar_packets"},
                                            {"/metadata", "/ouster/metadata"}};
  const nodelet::V_string no_arguments;
  ASSERT_TRUE(loader.load("/adapter", "range_image_mapping/Adapter", packets_remapping, no_arguments));
  ASSERT_TRUE(loader.load("/odometry", "range_image_mapping/Odometry", nodelet::M_string(), no_arguments));
  ASSERT_TRUE(loader.load("/mapper", "range_image_mapping/Mapper", nodelet::M_string(), no_arguments));

  // Until the replay is over: enough images and odometry, then 3 s of silence.
  ros::WallTime last_image = ros::WallTime::now();
  std::size_t seen = 0;
  spinUntil(
      [&] {
        if (first.messages.size() != seen) seen = first.messages.size(), last_image = ros::WallTime::now();
        return int(seen) >= min_images && int(odometry.size()) >= min_images - 1 &&
               (ros::WallTime::now() - last_image).toSec() > 3.0;
      },
      timeout_s);
  ASSERT_GE(int(first.messages.size()), min_images) << "range images within " << timeout_s << " s";
  ASSERT_EQ(first.messages.size(), second.messages.size());

  // One object per scan, shared by both subscribers, and the publisher's own.
  std::size_t shared = 0, deserialized = 0;
  for (std::size_t i = 0; i < first.messages.size(); ++i) {
    shared += first.messages[i] == second.messages[i];
    deserialized += factory.made(first.messages[i].get()) || factory.made(second.messages[i].get());
  }
  EXPECT_EQ(shared, first.messages.size()) << "scans the two subscribers got as different objects";
  EXPECT_EQ(deserialized, 0u) << "scans that reached this process serialized (a by-value publish)";
  EXPECT_EQ(factory.count(), 0u) << "messages deserialized for the test's subscribers";
  std::map<const LidarRangeImage*, int> addresses;
  for (const ImagePtr& message : first.messages) ++addresses[message.get()];
  EXPECT_EQ(addresses.size(), first.messages.size()) << "one object published twice";

  // The Odometry and the Mapper, in the same manager, used them.
  EXPECT_GE(int(odometry.size()), min_images - 1);
  SaveMesh save;
  save.request.path = sequence_dir + "/zero_copy_mesh.ply";
  ASSERT_TRUE(ros::service::call("/mapper/save_mesh", save));
  ASSERT_TRUE(save.response.success) << save.response.message;
  std::smatch scans;
  ASSERT_TRUE(std::regex_search(save.response.message, scans, std::regex("from ([0-9]+) scans")))
      << save.response.message;
  EXPECT_GE(std::stoi(scans[1]), min_images - 2) << save.response.message;

  // Nothing changed any message after its publication: not the Adapter (a
  // reused buffer), not the Odometry, not the Mapper.
  std::size_t changed = 0;
  for (std::size_t i = 0; i < first.messages.size(); ++i) changed += contentHash(*first.messages[i]) != first.hashes[i];
  EXPECT_EQ(changed, 0u) << "messages changed after they were published";
  std::cout << first.messages.size() << " range images: " << shared << " one object at both subscribers, "
            << deserialized << " deserialized, " << changed << " changed by the end; " << odometry.size()
            << " odometry messages; " << save.response.message << "\n";

  // Unload while the subscribers still hold messages: the nodelets must not need them.
  loader.clear();
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "zero_copy");
}
