// Adapter: Ouster packets or PointCloud2 in, self-describing LidarRangeImage out.
//
// Every callback runs on the nodelet's single-threaded queue (getNodeHandle),
// so the members need no locks. Nothing thrown by bad input leaves a callback:
// it is counted, logged (throttled) and the next message is processed.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/cloud_stream_checks.h"
#include "range_image_mapping/io/sensor_file.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/receive_time_stamps.h"
#include "range_image_mapping/ros/parameters.h"
#include "range_image_mapping/ros/steady_throttle.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/ros/wall_clock_diagnostics.h"
#include "range_image_mapping/scan_batcher.h"
#include "range_image_mapping/sensor_catalog.h"
#include "range_image_mapping/sensor_model_estimation.h"
#include "range_image_mapping/sensor_model_report.h"

#include <geometry_msgs/TransformStamped.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/String.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <topic_tools/shape_shifter.h>

#include <boost/make_shared.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

// Drops the adapter saw itself, on top of the batcher's and the projection's.
struct AdapterDrops {
  std::size_t foreign_packet_messages = 0;  // not an Ouster PacketMsg, or a bad length prefix
  std::size_t packets_without_metadata = 0;  // pending queue full before metadata arrived
  std::size_t rejected_clouds = 0;           // PointCloud2 that could not be converted
  std::size_t failed_scans = 0;              // a scan that could not become an image

  std::size_t total() const {
    return foreign_packet_messages + packets_without_metadata + rejected_clouds + failed_scans;
  }
};

void accumulate(BatcherStatistics& total, const BatcherStatistics& part) {
  total.packets += part.packets;
  total.wrong_size += part.wrong_size;
  total.malformed += part.malformed;
  total.bad_checksum += part.bad_checksum;
  total.stale += part.stale;
  total.scans += part.scans;
  total.incomplete_scans += part.incomplete_scans;
  total.missing_columns += part.missing_columns;
}

// The image destaggered (as the scene looks) for rviz's Image display: mono16
// millimetres, 0 = no return as the sensor sends it; ranges past 65.535 m
// saturate. rviz scales it with the display's min and max.
void toDisplayImage(const RangeImage& image, const std_msgs::Header& header, sensor_msgs::Image& display) {
  const RangeImage destaggered = image.destaggered();
  display.header = header;
  display.height = static_cast<uint32_t>(destaggered.rows());
  display.width = static_cast<uint32_t>(destaggered.columns());
  display.encoding = "mono16";
  display.is_bigendian = 0;
  display.step = display.width * sizeof(uint16_t);
  display.data.resize(std::size_t(display.step) * display.height);
  uint16_t* pixels = reinterpret_cast<uint16_t*>(display.data.data());
  for (std::size_t i = 0; i < destaggered.range.size(); ++i) {
    const float range = destaggered.range[i];
    pixels[i] = isValidRange(range) ? static_cast<uint16_t>(std::min(std::lround(range * 1000.0f), 65535l)) : 0;
  }
}

// The sensor model of PointCloud2 input, fixed by the parameters (nullptr
// with intrinsics ring or estimate: it comes from the first clouds), and the
// sensor file's ring map. Throws ParameterError naming the parameter that
// gives no model.
LidarModelConstPtr cloudModel(const AdapterParameters& parameters, const ros::NodeHandle& private_node,
                              std::vector<int>& ring_to_row) {
  switch (parameters.cloud_intrinsics) {
    case CloudIntrinsicsSource::kSensor:
      try {
        io::SensorFile sensor = io::readSensorFile(parameters.sensor);
        ring_to_row = std::move(sensor.ring_to_row);
        return std::make_shared<const LidarModel>(std::move(sensor.intrinsics));
      } catch (const std::exception& error) {
        throw ParameterError("parameter " + private_node.resolveName("sensor") + " ('" + parameters.sensor +
                             "') gives no sensor model: " + error.what());
      }
    case CloudIntrinsicsSource::kSynthetic:
      try {
        return std::make_shared<const LidarModel>(
            LidarIntrinsics::synthetic(parameters.rows, parameters.columns, parameters.fov_up_deg * M_PI / 180.0,
                                       parameters.fov_down_deg * M_PI / 180.0));
      } catch (const std::exception& error) {
        throw ParameterError("parameters " + private_node.resolveName("rows") + ", columns, fov_up_deg and "
                             "fov_down_deg give no sensor model: " + error.what());
      }
    case CloudIntrinsicsSource::kOuster:
      try {
        return std::make_shared<const LidarModel>(loadOusterMetadata(parameters.metadata_file).intrinsics);
      } catch (const std::exception& error) {
        throw ParameterError("parameter " + private_node.resolveName("metadata_file") + " ('" +
                             parameters.metadata_file + "') gives no sensor model: " + error.what());
      }
    case CloudIntrinsicsSource::kRing:
    case CloudIntrinsicsSource::kEstimate:
      break;
  }
  return nullptr;
}

}  // namespace

class AdapterNodelet : public nodelet::Nodelet {
 public:
  void onInit() override;

 private:
  // Ouster packets.
  void startOusterInput();
  void onPacketMessage(const ros::MessageEvent<topic_tools::ShapeShifter const>& event);
  void onMetadataMessage(const std_msgs::String::ConstPtr& message);
  void useMetadata(const OusterMetadata& metadata, const std::string& origin);
  void feedPacket(const uint8_t* data, std::size_t size, const ros::Time& receipt);
  void onScan(const LidarScan& scan);
  void onIdleCheck(const ros::SteadyTimerEvent&);
  // What was lost or repaired on the packet path, as the log summary says it.
  void diagnosePackets(diagnostic_updater::DiagnosticStatusWrapper& status);
  std::unique_ptr<ScanBatcher> makeBatcher(const OusterMetadata& metadata);
  void replaceBatcher(std::unique_ptr<ScanBatcher> fresh);

  // PointCloud2.
  void startPointCloudInput();
  void onPointCloud(const sensor_msgs::PointCloud2::ConstPtr& message);
  void transformSensorFrameToLidarFrame(PointCloudInput& cloud) const;
  // The clouds' own checks: frame, missing clouds, column order. Once per problem.
  void checkCloudStream(const PointCloudInput& cloud, const std::string& frame_id);
  // intrinsics estimate: true once the model is estimated from the clouds held.
  bool estimateCloudModel(const PointCloudInput& cloud, const std_msgs::Header& header);
  void projectAndPublish(PointCloudInput& cloud, const std_msgs::Header& header);
  void checkModelFit(const ProjectionStatistics& statistics);
  // A setting that contradicts the data: logged once, kept for diagnostics.
  void warnSetting(const std::string& key, const std::string& message);
  void diagnoseClouds(diagnostic_updater::DiagnosticStatusWrapper& status);

  void publish(const RangeImage& image, const std_msgs::Header& header);
  // stamp_source receive_time: the receipt of the scan's first packet, kept increasing.
  ros::Time receiveStamp(uint32_t frame_id, uint64_t sensor_stamp_ns);
  void publishStaticTransform(const LidarIntrinsics& intrinsics);
  void onStatisticsTimer(const ros::SteadyTimerEvent&);
  BatcherStatistics batcherStatistics() const;

  AdapterParameters parameters_;
  ros::Publisher range_image_publisher_;
  ros::Publisher cloud_publisher_;
  ros::Publisher display_publisher_;  // range_image_display, for rviz
  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> static_transform_broadcaster_;
  ros::Subscriber input_subscriber_;
  ros::Subscriber metadata_subscriber_;
  ros::SteadyTimer idle_timer_;
  ros::SteadyTimer statistics_timer_;

  // Ouster state: one model and batcher per metadata.
  std::optional<OusterMetadata> metadata_;
  bool metadata_from_file_ = false;
  LidarModelConstPtr model_;
  std::unique_ptr<ScanBatcher> batcher_;
  std::vector<uint8_t> serialized_packet_;  // reused per packet
  // Packets that arrived before the metadata (a latched topic may connect late).
  struct PendingPacket {
    std::vector<uint8_t> bytes;
    ros::Time receipt;
  };
  std::deque<PendingPacket> pending_packets_;
  // A looping bag replays frame ids the batcher has already emitted, which it
  // refuses as stale. When ROS time goes back, the next stale packet within a
  // revolution's worth of packets starts a new scan sequence, fed with the
  // stale packets just before it: /clock ticks slower than packets arrive, so
  // the jump shows a few packets late, and packets of the old pass still
  // queued after the jump complete the old scan rather than cut it short.
  std::deque<PendingPacket> stale_packets_;
  static constexpr std::size_t kStalePacketLimit = 512;
  int time_jump_packets_left_ = 0;
  // Receipt time of the first packet of the current and the previous frame: a
  // scan is emitted on its last column, on the next frame's first packet, or on
  // flush, so it is one of these two.
  uint32_t current_frame_id_ = 0, previous_frame_id_ = 0;
  ros::Time current_frame_receipt_, previous_frame_receipt_;
  // Receive-time stamps: the sensor clock mapped onto ROS time.
  std::optional<ReceiveTimeStamps> receive_stamps_;
  ReceiveTimeStamps::Counts stampCounts() const {
    return receive_stamps_ ? receive_stamps_->counts() : ReceiveTimeStamps::Counts{};
  }
  ReceiveTimeStamps::Counts logged_stamp_counts_;
  bool revolution_in_progress_ = false;
  ros::SteadyTime last_packet_time_;
  ros::SteadyTime first_idle_check_;  // the first of the onIdleCheck calls in a row that found no packet
  ros::Time last_receipt_;  // to notice ROS time jumping back (a bag loop)
  // diagnosePackets, per kind of problem (drops, incomplete scans, restamped
  // scans and clock steps, late or early receipts): the count at its previous
  // call, and when it last grew.
  std::array<std::size_t, 4> diagnosed_packet_problems_{};
  std::array<ros::SteadyTime, 4> last_packet_problem_;

  // PointCloud2 state.
  PointCloudInput cloud_input_;  // reused per cloud
  LidarModelConstPtr cloud_model_;
  std::vector<int> ring_to_row_;  // intrinsics ring, or a sensor file's
  // intrinsics estimate: the first clouds, held until the model is estimated from them.
  struct HeldCloud {
    PointCloudInput cloud;
    std_msgs::Header header;
  };
  std::vector<HeldCloud> held_clouds_;
  CloudGapCounter cloud_gaps_;
  std::size_t logged_missing_clouds_ = 0;
  bool column_order_checked_ = false;
  bool rings_checked_ = false;
  ColumnOrder organized_column_order_ = ColumnOrder::kDestaggered;  // the setting, or the data's when they differ
  ProjectionStatistics fit_check_statistics_;  // the first clouds of a model, for one check of the fit
  std::size_t fit_check_clouds_ = 0;
  std::size_t clouds_ = 0;
  std::map<std::string, std::string> setting_warnings_;
  std::unique_ptr<WallClockDiagnostics> diagnostics_;

  // Counters for the throttled summaries.
  BatcherStatistics retired_batcher_statistics_;  // of batchers replaced by new metadata
  ProjectionStatistics projection_statistics_;
  AdapterDrops drops_;
  BatcherStatistics logged_batcher_statistics_;
  ProjectionStatistics logged_projection_statistics_;
  AdapterDrops logged_drops_;
  SteadyThrottle foreign_packet_log_, no_metadata_log_, packet_error_log_, scan_error_log_, restamp_log_,
      receipt_log_, flush_error_log_, cloud_error_log_;
};

void AdapterNodelet::onInit() {
  ros::NodeHandle& node = getNodeHandle();
  startOrRefuseLoad(getName(), "Adapter", [&] {
    parameters_ = readAdapterParameters(getPrivateNodeHandle());
    if (parameters_.input == AdapterInput::kPointCloud)
      cloud_model_ = cloudModel(parameters_, getPrivateNodeHandle(), ring_to_row_);
  });
  range_image_publisher_ = node.advertise<LidarRangeImage>("range_image", 4);
  if (parameters_.publish_cloud) cloud_publisher_ = node.advertise<sensor_msgs::PointCloud2>("cloud", 4);
  display_publisher_ = node.advertise<sensor_msgs::Image>("range_image_display", 2);
  if (parameters_.publish_static_tf)
    static_transform_broadcaster_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
  statistics_timer_ = node.createSteadyTimer(ros::WallDuration(parameters_.statistics_period_s),
                                             &AdapterNodelet::onStatisticsTimer, this);
  if (parameters_.input == AdapterInput::kOusterPackets)
    startOusterInput();
  else
    startPointCloudInput();
}

// ------------------------------------------------------------ Ouster packets

void AdapterNodelet::startOusterInput() {
  ros::NodeHandle& node = getNodeHandle();
  if (!parameters_.metadata_file.empty()) {
    try {
      useMetadata(loadOusterMetadata(parameters_.metadata_file), "file " + parameters_.metadata_file);
      metadata_from_file_ = true;
    } catch (const std::exception& error) {
      NODELET_ERROR("metadata_file %s unusable, waiting for the metadata topic instead: %s",
                    parameters_.metadata_file.c_str(), error.what());
    }
  }
  metadata_subscriber_ =
      node.subscribe("metadata", 1, &AdapterNodelet::onMetadataMessage, this);
  input_subscriber_ = node.subscribe("lidar_packets", parameters_.packet_queue_size,
                                     &AdapterNodelet::onPacketMessage, this);
  diagnostics_ = std::make_unique<WallClockDiagnostics>(getNodeHandle(), getPrivateNodeHandle(), getName(),
                                                        "lidar_adapter");
  diagnostics_->updater().add("Ouster packets", this, &AdapterNodelet::diagnosePackets);
  if (parameters_.flush_after_idle_s > 0)
    idle_timer_ = node.createSteadyTimer(ros::WallDuration(parameters_.flush_after_idle_s / 2),
                                         &AdapterNodelet::onIdleCheck, this);
  NODELET_INFO("Adapter: Ouster packets from %s, metadata from %s, range images on %s",
               input_subscriber_.getTopic().c_str(),
               metadata_from_file_ ? parameters_.metadata_file.c_str()
                                   : metadata_subscriber_.getTopic().c_str(),
               range_image_publisher_.getTopic().c_str());
}

void AdapterNodelet::onMetadataMessage(const std_msgs::String::ConstPtr& message) {
  try {
    if (metadata_from_file_) {
      NODELET_INFO_ONCE("metadata topic ignored: metadata_file %s is set",
                        parameters_.metadata_file.c_str());
      return;
    }
    if (metadata_ && metadata_->json == message->data) return;  // latched re-delivery
    OusterMetadata metadata;
    try {
      metadata = parseOusterMetadata(message->data);
    } catch (const MetadataError& error) {
      NODELET_ERROR("metadata on %s rejected%s: %s", metadata_subscriber_.getTopic().c_str(),
                    metadata_ ? ", keeping the previous one" : "", error.what());
      return;
    }
    useMetadata(metadata, "topic " + metadata_subscriber_.getTopic());
  } catch (const std::exception& error) {
    NODELET_ERROR("metadata on %s not used: %s", metadata_subscriber_.getTopic().c_str(), error.what());
  }
}

// Builds the model and batcher of metadata first, so metadata the core
// rejects leaves the previous ones in place; then hands over.
void AdapterNodelet::useMetadata(const OusterMetadata& metadata, const std::string& origin) {
  auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  auto batcher = makeBatcher(metadata);
  if (parameters_.ouster_return == ReturnIndex::kSecond &&
      metadata.profile != UdpProfile::kRng19Rfl8Sig16Nir16Dual)
    NODELET_WARN("ouster_return is second but profile %s has one return: the images will be empty",
                 toString(metadata.profile));

  // The revolution in progress belongs to the old metadata: it is flushed
  // with the old model before the new one takes over.
  replaceBatcher(std::move(batcher));
  model_ = std::move(model);
  metadata_ = metadata;
  // One stamp sequence across metadata changes, so stamps keep increasing through a switch.
  const int64_t period_ns = static_cast<int64_t>(std::llround(1e9 / metadata.frequency_hz));
  if (receive_stamps_)
    receive_stamps_->setNominalPeriod(period_ns);
  else
    receive_stamps_.emplace(period_ns);
  NODELET_INFO("Ouster metadata from %s: %s %s, %s, %s, %dx%d", origin.c_str(),
               metadata.prod_line.c_str(), metadata.serial.c_str(), metadata.firmware.c_str(),
               toString(metadata.profile), model_->rows(), model_->columns());
  publishStaticTransform(model_->intrinsics());

  while (!pending_packets_.empty()) {
    const PendingPacket& packet = pending_packets_.front();
    feedPacket(packet.bytes.data(), packet.bytes.size(), packet.receipt);
    pending_packets_.pop_front();
  }
}

std::unique_ptr<ScanBatcher> AdapterNodelet::makeBatcher(const OusterMetadata& metadata) {
  return std::make_unique<ScanBatcher>(metadata, [this](const LidarScan& scan) { onScan(scan); });
}

// Publishes what the old batcher holds, keeps its counts, and hands over.
void AdapterNodelet::replaceBatcher(std::unique_ptr<ScanBatcher> fresh) {
  if (batcher_) {
    batcher_->flush();
    accumulate(retired_batcher_statistics_, batcher_->statistics());
  }
  batcher_ = std::move(fresh);
  revolution_in_progress_ = false;
  current_frame_receipt_ = previous_frame_receipt_ = ros::Time();
}

void AdapterNodelet::onPacketMessage(const ros::MessageEvent<topic_tools::ShapeShifter const>& event) {
  try {
    // When roscpp received the packet, not when this callback runs: on a
    // loaded machine the nodelet's queue runs seconds behind, and a replay's
    // clock may have stopped by then (the bag ended), which would stamp the
    // last revolutions alike.
    const ros::Time receipt = event.getReceiptTime();
    const topic_tools::ShapeShifter::ConstPtr message = event.getConstMessage();
    last_packet_time_ = ros::SteadyTime::now();
    if (batcher_ && !last_receipt_.isZero() && receipt < last_receipt_) {
      NODELET_WARN("ROS time jumped back by %.3f s (bag loop or restart)", (last_receipt_ - receipt).toSec());
      if (receive_stamps_) receive_stamps_->restart();
      const PacketFormat& format = batcher_->format();
      time_jump_packets_left_ = format.columns() / format.columnsPerPacket() + 1;
    }
    last_receipt_ = receipt;
    PacketBytes packet;
    try {
      packet = ousterPacketBytes(*message, serialized_packet_);
    } catch (const MessageConversionError& error) {
      ++drops_.foreign_packet_messages;
      if (foreign_packet_log_.allow(parameters_.statistics_period_s))
        NODELET_ERROR("dropped on %s: %s", input_subscriber_.getTopic().c_str(), error.what());
      return;
    }
    if (!batcher_) {
      // Keep the newest packets: the oldest belong to a revolution that will be incomplete anyway.
      const bool full = static_cast<int>(pending_packets_.size()) >= parameters_.pending_packet_limit;
      if (full) {
        ++drops_.packets_without_metadata;
        if (no_metadata_log_.allow(parameters_.statistics_period_s))
          NODELET_WARN("no Ouster metadata yet (topic %s or parameter metadata_file): dropping "
                       "packets, %zu so far",
                       metadata_subscriber_.getTopic().c_str(), drops_.packets_without_metadata);
        if (pending_packets_.empty()) return;  // pending_packet_limit 0: keep nothing
        pending_packets_.pop_front();
      }
      pending_packets_.push_back({std::vector<uint8_t>(packet.data, packet.data + packet.size), receipt});
      return;
    }
    feedPacket(packet.data, packet.size, receipt);
  } catch (const std::exception& error) {
    if (packet_error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("packet on %s dropped: %s", input_subscriber_.getTopic().c_str(), error.what());
  }
}

void AdapterNodelet::feedPacket(const uint8_t* data, std::size_t size, const ros::Time& receipt) {
  const PacketFormat& format = batcher_->format();
  if (size == format.packetSize()) {
    const uint32_t frame_id = format.frameId(data);
    if (frame_id != current_frame_id_ || current_frame_receipt_.isZero()) {
      previous_frame_id_ = current_frame_id_;
      previous_frame_receipt_ = current_frame_receipt_;
      current_frame_id_ = frame_id;
      current_frame_receipt_ = receipt;
    }
  }
  revolution_in_progress_ = true;
  const std::size_t stale_before = batcher_->statistics().stale;
  batcher_->addPacket(data, size);  // may call onScan
  if (batcher_->statistics().stale == stale_before) {
    stale_packets_.clear();
    if (time_jump_packets_left_ > 0) --time_jump_packets_left_;
    return;
  }
  if (stale_packets_.size() < kStalePacketLimit)
    stale_packets_.push_back({std::vector<uint8_t>(data, data + size), receipt});
  if (time_jump_packets_left_ > 0) {
    time_jump_packets_left_ = 0;
    NODELET_WARN("frame ids repeat after ROS time went back: starting a new scan sequence");
    replaceBatcher(makeBatcher(*metadata_));
    std::deque<PendingPacket> start_of_pass;
    start_of_pass.swap(stale_packets_);
    for (const PendingPacket& early : start_of_pass)
      feedPacket(early.bytes.data(), early.bytes.size(), early.receipt);
  }
}

void AdapterNodelet::onScan(const LidarScan& scan) {
  revolution_in_progress_ = false;
  try {
    if (range_image_publisher_.getNumSubscribers() == 0 && display_publisher_.getNumSubscribers() == 0 &&
        (!cloud_publisher_ || cloud_publisher_.getNumSubscribers() == 0))
      return;
    const RangeImage image = toRangeImage(scan, model_, parameters_.ouster_return);
    std_msgs::Header header;
    header.frame_id = parameters_.lidar_frame;
    if (parameters_.stamp_source == StampSource::kSensorClock)
      header.stamp.fromNSec(image.stamp_ns);
    else
      header.stamp = receiveStamp(scan.frame_id, image.stamp_ns);
    publish(image, header);
  } catch (const std::exception& error) {
    ++drops_.failed_scans;
    if (scan_error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("scan %u dropped: %s", scan.frame_id, error.what());
  }
}

ros::Time AdapterNodelet::receiveStamp(uint32_t frame_id, uint64_t sensor_stamp_ns) {
  const ros::Time receipt = frame_id == current_frame_id_ && !current_frame_receipt_.isZero() ? current_frame_receipt_
                            : frame_id == previous_frame_id_ && !previous_frame_receipt_.isZero()
                                ? previous_frame_receipt_
                                : ros::Time::now();
  if (!receive_stamps_) return receipt;
  const ReceiveTimeStamps::Stamp stamp =
      receive_stamps_->next(static_cast<int64_t>(receipt.toNSec()), static_cast<int64_t>(sensor_stamp_ns));
  ros::Time stamped;
  stamped.fromNSec(static_cast<uint64_t>(stamp.stamp_ns));
  const double delay_s = static_cast<double>(stamp.receipt_delay_ns) * 1e-9;
  if ((stamp.clock_step || stamp.repaired) && restamp_log_.allow(parameters_.statistics_period_s)) {
    if (stamp.clock_step)
      NODELET_WARN("scan %u: received at %.3f s, %.3f s off the sensor clock's mapping onto ROS time: ROS time or "
                   "the sensor clock stepped (host clock set, a bag loop, the sensor's clock reset or "
                   "synchronised). Stamps follow the receipt from here (%zu clock steps so far)",
                   frame_id, receipt.toSec(), delay_s, receive_stamps_->counts().clock_steps);
    else
      NODELET_WARN("scan %u: its stamp would not have advanced past the previous scan's (received at %.3f s): "
                   "stamped %.3f s, the sensor clock's interval (or the nominal period) after it, so that no scan "
                   "is refused as out of order. The sensor clock stands still or ROS time stalls; with a "
                   "PTP-synchronised sensor use stamp_source: sensor_clock. %zu scans restamped so far",
                   frame_id, receipt.toSec(), stamped.toSec(), receive_stamps_->counts().restamped);
  } else if ((stamp.receipt_delay_ns >= ReceiveTimeStamps::kLateReceipt_ns ||
              stamp.receipt_delay_ns <= -ReceiveTimeStamps::kEarlyReceipt_ns) &&
             receipt_log_.allow(parameters_.statistics_period_s)) {
    if (stamp.receipt_delay_ns > 0)
      NODELET_WARN("scan %u read %.2f s late: the process stalled or fell behind (heavy load, a paused machine, "
                   "packets queued). Stamped from the sensor clock, not the late receipt; %zu scans late so far",
                   frame_id, delay_s, receive_stamps_->counts().late);
    else
      NODELET_WARN("scan %u received %.2f s before its sensor time mapped onto ROS time: ROS time stood still or "
                   "lagged (a bag's /clock delivered late on a loaded machine: replay slower, e.g. rate:=0.5). "
                   "Stamped from the sensor clock; %zu scans early so far",
                   frame_id, -delay_s, receive_stamps_->counts().early);
  }
  return stamped;
}

// WARN while anything was dropped or restamped within the last statistics
// period, naming what; the totals since start always.
void AdapterNodelet::diagnosePackets(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const BatcherStatistics batcher = batcherStatistics();
  const std::size_t packet_drops = batcher.wrong_size + batcher.malformed + batcher.bad_checksum + batcher.stale;
  const ReceiveTimeStamps::Counts stamps = stampCounts();
  const std::array<std::size_t, 4> problems{packet_drops + drops_.total(), batcher.incomplete_scans,
                                            stamps.restamped + stamps.clock_steps, stamps.late + stamps.early};
  const ros::SteadyTime now = ros::SteadyTime::now();
  std::array<bool, 4> recent{};
  for (std::size_t kind = 0; kind < problems.size(); ++kind) {
    if (problems[kind] != diagnosed_packet_problems_[kind]) last_packet_problem_[kind] = now;
    diagnosed_packet_problems_[kind] = problems[kind];
    recent[kind] = !last_packet_problem_[kind].isZero() &&
                   (now - last_packet_problem_[kind]).toSec() < parameters_.statistics_period_s;
  }
  if (!metadata_) {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                   "no Ouster metadata yet: publish it (latched) on " + metadata_subscriber_.getTopic() +
                       " or set metadata_file; packets wait for it");
  } else if (batcher.packets == 0) {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no packets on " + input_subscriber_.getTopic());
  } else if (recent[0] || recent[1] || recent[2] || recent[3]) {
    std::string summary = "in the last " + std::to_string(int(parameters_.statistics_period_s)) + " s:";
    if (recent[0]) summary += " packets or scans dropped (see the counts);";
    if (recent[1])
      summary += " incomplete scans (packets lost on the network, or packet_queue_size too small for the replay);";
    if (recent[2])
      summary += " scans restamped or clock steps (ROS time or the sensor clock stood still or was set: see the "
                 "log; with a synchronised sensor use stamp_source sensor_clock);";
    if (recent[3])
      summary += " scans received late (the process stalled or fell behind) or early (a late /clock on a loaded "
                 "machine: replay slower), stamped from the sensor clock;";
    summary.pop_back();
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, summary);
  } else {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "decoding");
  }
  status.add("packets", batcher.packets);
  status.add("scans", batcher.scans);
  status.add("incomplete scans", batcher.incomplete_scans);
  status.add("missing columns", batcher.missing_columns);
  status.add("packets dropped: wrong size", batcher.wrong_size);
  status.add("packets dropped: malformed", batcher.malformed);
  status.add("packets dropped: bad checksum", batcher.bad_checksum);
  status.add("packets dropped: stale", batcher.stale);
  status.add("messages dropped: not Ouster packets", drops_.foreign_packet_messages);
  status.add("packets dropped: no metadata", drops_.packets_without_metadata);
  status.add("scans failed", drops_.failed_scans);
  status.add("scans restamped (stamp would not advance)", stamps.restamped);
  status.add("clock steps (stamps follow the receipt anew)", stamps.clock_steps);
  status.add("scans received late (stall)", stamps.late);
  status.add("scans received early (ROS time stood still)", stamps.early);
  status.add("stamp source", parameters_.stamp_source == StampSource::kSensorClock ? "sensor_clock" : "receive_time");
}

// A replay that ends, or a sensor that stops, leaves its last revolution in the
// batcher: publish it once packets have stopped for flush_after_idle.
void AdapterNodelet::onIdleCheck(const ros::SteadyTimerEvent&) {
  try {
    if (!batcher_ || !revolution_in_progress_) return;
    const ros::SteadyTime now = ros::SteadyTime::now();
    if ((now - last_packet_time_).toSec() < parameters_.flush_after_idle_s) {
      first_idle_check_ = ros::SteadyTime();
      return;
    }
    // Idle on two checks a quarter of flush_after_idle apart: after a stall of
    // this process its timer's callbacks can run before the packets queued
    // meanwhile, and would cut their revolution short.
    if (first_idle_check_.isZero()) first_idle_check_ = now;
    if ((now - first_idle_check_).toSec() < parameters_.flush_after_idle_s / 4) return;
    first_idle_check_ = ros::SteadyTime();
    revolution_in_progress_ = false;
    batcher_->flush();
  } catch (const std::exception& error) {
    if (flush_error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("flush failed: %s", error.what());
  }
}

// ------------------------------------------------------------ PointCloud2

void AdapterNodelet::startPointCloudInput() {
  if (parameters_.cloud_intrinsics == CloudIntrinsicsSource::kOuster)
    publishStaticTransform(cloud_model_->intrinsics());
  organized_column_order_ = parameters_.organized_column_order;
  diagnostics_ = std::make_unique<WallClockDiagnostics>(getNodeHandle(), getPrivateNodeHandle(), getName(),
                                                        "lidar_adapter");
  diagnostics_->updater().add("point clouds", this, &AdapterNodelet::diagnoseClouds);
  input_subscriber_ = getNodeHandle().subscribe("points", parameters_.cloud_queue_size,
                                                &AdapterNodelet::onPointCloud, this);
  std::string model = "estimated from the first " + std::to_string(parameters_.estimate_clouds) + " clouds";
  if (parameters_.cloud_intrinsics == CloudIntrinsicsSource::kRing) model = "from the first cloud's ring field";
  if (cloud_model_)
    model = cloud_model_->intrinsics().sensor_model + ", " + describeSensorModel(cloud_model_->intrinsics());
  NODELET_INFO("Adapter: PointCloud2 from %s, range images on %s; sensor model %s",
               input_subscriber_.getTopic().c_str(), range_image_publisher_.getTopic().c_str(), model.c_str());
}

// The Ouster driver publishes its clouds in the sensor frame; the model's
// geometry is in the lidar frame.
void AdapterNodelet::transformSensorFrameToLidarFrame(PointCloudInput& cloud) const {
  const Eigen::Isometry3f sensor_to_lidar = cloud_model_->intrinsics().lidar_to_sensor.inverse().cast<float>();
  for (Eigen::Vector3f& point : cloud.points) point = sensor_to_lidar * point;
}

void AdapterNodelet::onPointCloud(const sensor_msgs::PointCloud2::ConstPtr& message) {
  try {
    fromPointCloud2(*message, cloud_input_);
    ++clouds_;
    std_msgs::Header header = message->header;
    // The scan time is the points' own (the earliest point's time) where the
    // cloud has per-point times: drivers stamp headers with jitter.
    header.stamp.fromNSec(cloud_input_.stamp_ns);
    checkCloudStream(cloud_input_, header.frame_id);
    if (header.frame_id.empty()) header.frame_id = parameters_.lidar_frame;
    if (parameters_.cloud_intrinsics == CloudIntrinsicsSource::kOuster &&
        header.frame_id == parameters_.sensor_frame) {
      transformSensorFrameToLidarFrame(cloud_input_);
      header.frame_id = parameters_.lidar_frame;
    }
    if (!cloud_model_ && parameters_.cloud_intrinsics == CloudIntrinsicsSource::kRing) {
      RingIntrinsics ring_intrinsics = intrinsicsFromRings(cloud_input_, parameters_.columns);
      cloud_model_ = std::make_shared<const LidarModel>(std::move(ring_intrinsics.intrinsics));
      ring_to_row_ = std::move(ring_intrinsics.ring_to_row);
      NODELET_INFO("ring intrinsics from the cloud on %s: %d rings x %d columns",
                   input_subscriber_.getTopic().c_str(), cloud_model_->rows(), cloud_model_->columns());
    }
    if (!cloud_model_) {
      if (!estimateCloudModel(cloud_input_, header)) return;
      std::vector<HeldCloud> held;
      held.swap(held_clouds_);
      for (HeldCloud& cloud : held) projectAndPublish(cloud.cloud, cloud.header);
      return;
    }
    projectAndPublish(cloud_input_, header);
  } catch (const std::exception& error) {
    ++drops_.rejected_clouds;
    if (cloud_error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("PointCloud2 on %s dropped: %s", input_subscriber_.getTopic().c_str(), error.what());
  }
}

void AdapterNodelet::projectAndPublish(PointCloudInput& cloud, const std_msgs::Header& header) {
  // A ring field says how many beams the sensor has: a model with another
  // row count is another sensor (a VLP-32C read as a VLP-16).
  if (!rings_checked_ && !cloud.ring.empty() && ring_to_row_.empty()) {
    rings_checked_ = true;
    const int rings = *std::max_element(cloud.ring.begin(), cloud.ring.end()) + 1;
    if (rings != cloud_model_->rows())
      warnSetting("rings", "clouds on " + input_subscriber_.getTopic() + " carry " + std::to_string(rings) +
                               " rings but the sensor model (" + cloud_model_->intrinsics().sensor_model +
                               ") has " + std::to_string(cloud_model_->rows()) + " rows: set parameter " +
                               getPrivateNodeHandle().resolveName("sensor") + " to the " + std::to_string(rings) +
                               "-beam sensor, or leave it out to estimate the model from the clouds");
  }
  if (!column_order_checked_ && cloud.isOrganized()) {
    column_order_checked_ = true;
    const std::optional<ColumnOrder> found = detectOrganizedColumnOrder(cloud, *cloud_model_);
    const auto name = [](ColumnOrder order) { return order == ColumnOrder::kStaggered ? "staggered" : "destaggered"; };
    if (found && *found != parameters_.organized_column_order) {
      warnSetting("organized_columns",
                  std::string("the organized clouds on ") + input_subscriber_.getTopic() + " are " + name(*found) +
                      " but parameter " + getPrivateNodeHandle().resolveName("organized_columns") + " says " +
                      name(parameters_.organized_column_order) + ": set organized_columns: " + name(*found) +
                      " (ouster-ros destagger:=" + (*found == ColumnOrder::kDestaggered ? "true" : "false") +
                      "); the data's order is used");
      organized_column_order_ = *found;
    }
  }
  cloud.organized_column_order = organized_column_order_;
  ProjectionStatistics statistics;
  const RangeImage image = ring_to_row_.empty() ? projectPointCloud(cloud, cloud_model_, &statistics)
                                                : projectPointCloud(cloud, cloud_model_, ring_to_row_, &statistics);
  projection_statistics_.add(statistics);
  checkModelFit(statistics);
  publish(image, header);
}

bool AdapterNodelet::estimateCloudModel(const PointCloudInput& cloud, const std_msgs::Header& header) {
  held_clouds_.push_back({cloud, header});
  if (static_cast<int>(held_clouds_.size()) < parameters_.estimate_clouds) return false;
  std::vector<PointCloudInput> clouds;
  for (const HeldCloud& held : held_clouds_) clouds.push_back(held.cloud);
  SensorEstimate estimate;
  try {
    estimate = estimateSensorModel(clouds);
  } catch (const SensorEstimationError& error) {
    // More clouds may tell the beams apart; the oldest go once enough were tried.
    const std::size_t limit = std::size_t(10) * parameters_.estimate_clouds;
    if (held_clouds_.size() >= limit) {
      drops_.rejected_clouds += held_clouds_.size() - parameters_.estimate_clouds + 1;
      held_clouds_.erase(held_clouds_.begin(), held_clouds_.end() - (parameters_.estimate_clouds - 1));
    }
    if (cloud_error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("no sensor model could be estimated from %zu clouds on %s (%s): set parameter %s to a sensor "
                    "file or a named model (%s)",
                    clouds.size(), input_subscriber_.getTopic().c_str(), error.what(),
                    getPrivateNodeHandle().resolveName("sensor").c_str(), sensorCatalogNames().c_str());
    return false;
  }
  cloud_model_ = std::make_shared<const LidarModel>(estimate.intrinsics);
  ring_to_row_ = estimate.ring_to_row;
  NODELET_INFO("sensor model estimated from the first %zu clouds on %s: %s", clouds.size(),
               input_subscriber_.getTopic().c_str(), describeSensorEstimate(estimate).c_str());
  if (const std::optional<std::string> warning = sensorModelFitWarning(
          estimate.fit, "give the sensor's own model with parameter " +
                            getPrivateNodeHandle().resolveName("sensor") +
                            " (a sensor file, e.g. from rim sensor estimate on a recording, or one of " +
                            sensorCatalogNames() + ")"))
    warnSetting("sensor", "estimated " + *warning);
  // The estimate's own fit is the check: no second one.
  fit_check_clouds_ = std::size_t(parameters_.estimate_clouds);
  return true;
}

// The first clouds of a model given by the settings: does it explain them?
void AdapterNodelet::checkModelFit(const ProjectionStatistics& statistics) {
  if (fit_check_clouds_ >= std::size_t(parameters_.estimate_clouds)) return;
  fit_check_statistics_.add(statistics);
  if (++fit_check_clouds_ < std::size_t(parameters_.estimate_clouds)) return;
  const std::string parameter = parameters_.cloud_intrinsics == CloudIntrinsicsSource::kSensor   ? "sensor"
                                : parameters_.cloud_intrinsics == CloudIntrinsicsSource::kOuster ? "metadata_file"
                                : parameters_.cloud_intrinsics == CloudIntrinsicsSource::kRing   ? "columns"
                                                                                                 : "intrinsics";
  if (const std::optional<std::string> warning = projectionWarning(
          fit_check_statistics_,
          "check parameter " + getPrivateNodeHandle().resolveName(parameter) + " (" +
              cloud_model_->intrinsics().sensor_model + "), or drop " +
              getPrivateNodeHandle().resolveName("intrinsics") + " and " +
              getPrivateNodeHandle().resolveName("sensor") + " to estimate the model from the clouds"))
    warnSetting("model fit", "the first " + std::to_string(fit_check_clouds_) + " clouds: " + *warning);
}

void AdapterNodelet::checkCloudStream(const PointCloudInput& cloud, const std::string& frame_id) {
  // The launch's base frame defaults to sensor_frame: clouds in another frame
  // leave the Odometry waiting for a transform nobody publishes.
  if (!frame_id.empty() && frame_id != parameters_.sensor_frame && frame_id != parameters_.lidar_frame)
    warnSetting("sensor_frame", "clouds on " + input_subscriber_.getTopic() + " are in frame '" + frame_id +
                                    "' but parameter " + getPrivateNodeHandle().resolveName("sensor_frame") +
                                    " is '" + parameters_.sensor_frame + "' (and lidar_frame '" +
                                    parameters_.lidar_frame + "'): set sensor_frame:=" + frame_id +
                                    " (a launch argument) so that tf lookups use the clouds' frame");
  cloud_gaps_.add(cloud.stamp_ns);
  if (cloud_gaps_.early() > 0)
    warnSetting("stamps", "clouds on " + input_subscriber_.getTopic() + " are stamped less than half a period (" +
                              std::to_string(cloud_gaps_.periodSeconds()) +
                              " s) after the previous one: the driver stamps with jitter, e.g. the receive time "
                              "(ouster-ros timestamp_mode TIME_FROM_ROS_TIME): stamp with the sensor's clock "
                              "(TIME_FROM_INTERNAL_OSC, or PTP), or clouds with absolute per-point times");
}

void AdapterNodelet::warnSetting(const std::string& key, const std::string& message) {
  if (setting_warnings_.count(key)) return;
  setting_warnings_[key] = message;
  NODELET_WARN("%s", message.c_str());
}

void AdapterNodelet::diagnoseClouds(diagnostic_updater::DiagnosticStatusWrapper& status) {
  if (!setting_warnings_.empty()) {
    std::string summary;
    for (const auto& [key, message] : setting_warnings_) summary += (summary.empty() ? "" : " | ") + message;
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, summary);
  } else if (clouds_ == 0) {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no point clouds");
  } else {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "converting");
  }
  for (const auto& [key, message] : setting_warnings_) status.add("warning: " + key, message);
  status.add("clouds", clouds_);
  status.add("clouds missing (from the stamps)", cloud_gaps_.missing());
  status.add("sensor model", cloud_model_ ? cloud_model_->intrinsics().sensor_model : std::string("not yet"));
  const ProjectionStatistics& projected = projection_statistics_;
  const double measured = std::max<double>(1.0, double(projected.measured()));
  status.addf("kept share", "%.4f", projected.keptFraction());
  status.addf("outside the model share", "%.4f", double(projected.outside_model) / measured);
  status.addf("shared pixel share", "%.4f", double(projected.occluded) / measured);
  status.add("no-return points", projected.non_finite + projected.no_return);
}

// ------------------------------------------------------------ output

void AdapterNodelet::publish(const RangeImage& image, const std_msgs::Header& header) {
  if (range_image_publisher_.getNumSubscribers() > 0) {
    // Allocated here, published once and never touched again, so subscribers
    // in the same manager share it without a copy.
    const auto message = boost::make_shared<LidarRangeImage>();
    toMessage(image, header, *message);
    range_image_publisher_.publish(boost::shared_ptr<const LidarRangeImage>(message));
  }
  if (cloud_publisher_ && cloud_publisher_.getNumSubscribers() > 0) {
    const auto cloud = boost::make_shared<sensor_msgs::PointCloud2>();
    toPointCloud2(image, header, *cloud);
    cloud_publisher_.publish(boost::shared_ptr<const sensor_msgs::PointCloud2>(cloud));
  }
  if (display_publisher_.getNumSubscribers() > 0) {
    const auto display = boost::make_shared<sensor_msgs::Image>();
    toDisplayImage(image, header, *display);
    display_publisher_.publish(boost::shared_ptr<const sensor_msgs::Image>(display));
  }
}

// The transform sensor_frame -> lidar_frame that the driver would publish;
// replays of raw packets do not carry it.
void AdapterNodelet::publishStaticTransform(const LidarIntrinsics& intrinsics) {
  if (!static_transform_broadcaster_) return;
  const Eigen::Isometry3d& lidar_to_sensor = intrinsics.lidar_to_sensor;
  const Eigen::Quaterniond rotation(lidar_to_sensor.rotation());
  geometry_msgs::TransformStamped transform;
  transform.header.stamp = ros::Time::now();
  transform.header.frame_id = parameters_.sensor_frame;
  transform.child_frame_id = parameters_.lidar_frame;
  transform.transform.translation.x = lidar_to_sensor.translation().x();
  transform.transform.translation.y = lidar_to_sensor.translation().y();
  transform.transform.translation.z = lidar_to_sensor.translation().z();
  transform.transform.rotation.x = rotation.x();
  transform.transform.rotation.y = rotation.y();
  transform.transform.rotation.z = rotation.z();
  transform.transform.rotation.w = rotation.w();
  static_transform_broadcaster_->sendTransform(transform);
}

BatcherStatistics AdapterNodelet::batcherStatistics() const {
  BatcherStatistics total = retired_batcher_statistics_;
  if (batcher_) accumulate(total, batcher_->statistics());
  return total;
}

// One line per period while anything is being dropped, with the counts of the period.
void AdapterNodelet::onStatisticsTimer(const ros::SteadyTimerEvent&) {
  const BatcherStatistics batcher = batcherStatistics();
  const BatcherStatistics& before = logged_batcher_statistics_;
  const std::size_t packet_drops = (batcher.wrong_size - before.wrong_size) +
                                   (batcher.malformed - before.malformed) + (batcher.stale - before.stale) +
                                   (batcher.bad_checksum - before.bad_checksum);
  const std::size_t incomplete = batcher.incomplete_scans - before.incomplete_scans;
  const ProjectionStatistics& projected = projection_statistics_;
  const ProjectionStatistics& projected_before = logged_projection_statistics_;
  // NaN and (0, 0, 0) points are how drivers say "no return": not drops.
  const std::size_t point_drops = projected.outside_model - projected_before.outside_model;
  const std::size_t missing_clouds = cloud_gaps_.missing() - logged_missing_clouds_;
  const std::size_t other_drops = drops_.total() - logged_drops_.total() + missing_clouds;
  const ReceiveTimeStamps::Counts stamps = stampCounts();
  const std::size_t restamped = stamps.restamped - logged_stamp_counts_.restamped;
  const std::size_t clock_steps = stamps.clock_steps - logged_stamp_counts_.clock_steps;
  const std::size_t late = stamps.late - logged_stamp_counts_.late;
  const std::size_t early = stamps.early - logged_stamp_counts_.early;
  if (packet_drops + incomplete + point_drops + other_drops + restamped + clock_steps + late + early > 0) {
    NODELET_WARN(
        "last %.0f s: packets dropped %zu (wrong size %zu, malformed %zu, bad checksum %zu, stale %zu, "
        "not Ouster packets %zu, no metadata %zu); incomplete scans %zu (%zu columns missing); "
        "points outside the model %zu (no-return points, not counted: NaN %zu, at the origin %zu); "
        "clouds rejected %zu, missing %zu (from the stamps); "
        "scans failed %zu; scans restamped %zu, clock steps %zu, received late %zu, early %zu",
        parameters_.statistics_period_s, packet_drops, batcher.wrong_size - before.wrong_size,
        batcher.malformed - before.malformed, batcher.bad_checksum - before.bad_checksum,
        batcher.stale - before.stale,
        drops_.foreign_packet_messages - logged_drops_.foreign_packet_messages,
        drops_.packets_without_metadata - logged_drops_.packets_without_metadata, incomplete,
        batcher.missing_columns - before.missing_columns, point_drops,
        projected.non_finite - projected_before.non_finite,
        projected.no_return - projected_before.no_return,
        drops_.rejected_clouds - logged_drops_.rejected_clouds, missing_clouds,
        drops_.failed_scans - logged_drops_.failed_scans, restamped, clock_steps, late, early);
  }
  logged_stamp_counts_ = stamps;
  logged_batcher_statistics_ = batcher;
  logged_projection_statistics_ = projection_statistics_;
  logged_drops_ = drops_;
  logged_missing_clouds_ = cloud_gaps_.missing();
}

}  // namespace range_image_mapping

PLUGINLIB_EXPORT_CLASS(range_image_mapping::AdapterNodelet, nodelet::Nodelet)
