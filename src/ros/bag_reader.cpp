#include <board_calib/bag_reader.h>
#include <board_calib/conversions.h>

#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <algorithm>
#include <memory>
#include <set>

namespace board_calib {
namespace {

struct OpenBags {
  std::vector<std::unique_ptr<rosbag::Bag>> bags;
};

// A bag cut off while recording (no index at the end) is the usual cause of read errors.
std::string reindexHint(const std::string& path) {
  return " (a truncated or unindexed bag: run `rosbag reindex " + path +
         "` and retry with the reindexed file)";
}

std::string reindexHintAll(const std::vector<std::string>& paths) {
  std::string files;
  for (const auto& p : paths) files += (files.empty() ? "" : " ") + p;
  return reindexHint(files);
}

Status openAll(const std::vector<std::string>& paths, OpenBags* out) {
  if (paths.empty()) return Status::failure("no bag file given");
  for (const auto& path : paths) {
    auto bag = std::make_unique<rosbag::Bag>();
    try {
      bag->open(path, rosbag::bagmode::Read);
    } catch (const rosbag::BagException& e) {
      return Status::failure("cannot open bag '" + path + "': " + e.what() + reindexHint(path));
    }
    out->bags.push_back(std::move(bag));
  }
  return Status::success();
}

}  // namespace

Expected<std::map<std::string, size_t>> bagTopicCounts(const std::vector<std::string>& paths) {
  OpenBags open;
  const Status s = openAll(paths, &open);
  if (!s) return Expected<std::map<std::string, size_t>>::failure(s.reason);
  std::map<std::string, size_t> counts;
  try {
    for (const auto& bag : open.bags) {
      rosbag::View view(*bag);
      for (const auto* c : view.getConnections()) counts[c->topic] += 0;
      for (const auto& m : view) counts[m.getTopic()]++;
    }
  } catch (const std::exception& e) {
    return Expected<std::map<std::string, size_t>>::failure(std::string("error reading bag: ") +
                                                            e.what() + reindexHintAll(paths));
  }
  return counts;
}

Expected<std::vector<double>> topicTimes(const std::vector<std::string>& paths,
                                         const std::string& topic) {
  OpenBags open;
  const Status s = openAll(paths, &open);
  if (!s) return Expected<std::vector<double>>::failure(s.reason);
  std::vector<double> times;
  try {
    for (const auto& bag : open.bags) {
      rosbag::View view(*bag, rosbag::TopicQuery(topic));
      for (const auto& m : view) times.push_back(m.getTime().toSec());
    }
  } catch (const std::exception& e) {
    return Expected<std::vector<double>>::failure(std::string("error reading bag: ") + e.what() +
                                                  reindexHintAll(paths));
  }
  std::sort(times.begin(), times.end());
  return times;
}

namespace {

// Fails naming the first wanted topic no bag has, with every topic the bags do have.
Status checkTopicsPresent(rosbag::View& view, const std::vector<std::string>& wanted,
                          const OpenBags& open) {
  std::set<std::string> present;
  for (const auto* c : view.getConnections()) present.insert(c->topic);
  for (const auto& t : wanted) {
    if (!present.count(t)) {
      std::string available;
      for (const auto& bag : open.bags) {
        rosbag::View all(*bag);
        for (const auto* c : all.getConnections())
          available += (available.empty() ? "" : ", ") + c->topic + " [" + c->datatype + "]";
      }
      return Status::failure("topic '" + t + "' is not in the bag(s); available: " + available);
    }
  }
  return Status::success();
}

// One message to its callback, converted; what cannot be converted goes to on_bad_message.
void dispatch(const rosbag::MessageInstance& m, const std::set<std::string>& image_topics,
              const std::set<std::string>& info_topics, const std::set<std::string>& cloud_topics,
              const BagCallbacks& cb) {
  const std::string& topic = m.getTopic();
  if (image_topics.count(topic)) {
    const auto msg = m.instantiate<sensor_msgs::Image>();
    if (!msg) {
      if (cb.on_bad_message)
        cb.on_bad_message(topic, "not a sensor_msgs/Image (" + m.getDataType() + ")");
      return;
    }
    auto image = imageFromMsg(*msg);
    if (!image) {
      if (cb.on_bad_message) cb.on_bad_message(topic, image.error());
      return;
    }
    if (cb.on_image) cb.on_image({topic, msg->header.frame_id, msg->header.stamp.toSec(), *image});
  } else if (info_topics.count(topic)) {
    const auto msg = m.instantiate<sensor_msgs::CameraInfo>();
    if (!msg) {
      if (cb.on_bad_message)
        cb.on_bad_message(topic, "not a sensor_msgs/CameraInfo (" + m.getDataType() + ")");
      return;
    }
    auto in = fromCameraInfo(*msg);
    if (!in) {
      if (cb.on_bad_message) cb.on_bad_message(topic, in.error());
      return;
    }
    if (cb.on_camera_info) cb.on_camera_info(topic, msg->header.frame_id, *in);
  } else if (cloud_topics.count(topic)) {
    const auto msg = m.instantiate<sensor_msgs::PointCloud2>();
    if (!msg) {
      if (cb.on_bad_message)
        cb.on_bad_message(topic, "not a sensor_msgs/PointCloud2 (" + m.getDataType() + ")");
      return;
    }
    auto cloud = fromPointCloud2(*msg);
    if (!cloud) {
      if (cb.on_bad_message) cb.on_bad_message(topic, cloud.error());
      return;
    }
    if (cb.on_cloud) cb.on_cloud(topic, *cloud);
  }
}

}  // namespace

Status readBags(const std::vector<std::string>& paths, const BagTopics& topics,
                const BagCallbacks& cb) {
  OpenBags open;
  const Status s = openAll(paths, &open);
  if (!s) return s;
  std::set<std::string> image_topics(topics.image_topics.begin(), topics.image_topics.end());
  std::set<std::string> info_topics(topics.camera_info_topics.begin(),
                                    topics.camera_info_topics.end());
  std::set<std::string> cloud_topics(topics.cloud_topics.begin(), topics.cloud_topics.end());
  std::vector<std::string> wanted;
  for (const auto* set : {&image_topics, &info_topics, &cloud_topics})
    wanted.insert(wanted.end(), set->begin(), set->end());

  try {
    rosbag::View view;
    for (const auto& bag : open.bags) view.addQuery(*bag, rosbag::TopicQuery(wanted));
    if (Status st = checkTopicsPresent(view, wanted, open); !st) return st;
    for (const auto& m : view) dispatch(m, image_topics, info_topics, cloud_topics, cb);
  } catch (const rosbag::BagException& e) {
    return Status::failure(std::string("error reading bag: ") + e.what() + reindexHintAll(paths));
  } catch (const ros::Exception& e) {  // a corrupt message (serialization overrun)
    return Status::failure(std::string("corrupt message in bag: ") + e.what() +
                           reindexHintAll(paths));
  } catch (const std::exception& e) {
    return Status::failure(std::string("error reading bag: ") + e.what() + reindexHintAll(paths));
  }
  return Status::success();
}

Expected<BagFrameStats> readBagFrames(const std::vector<std::string>& paths,
                                      const BagTopics& topics, const BagFrameCallbacks& frames) {
  if (topics.image_topics.size() != topics.camera_info_topics.size())
    return Expected<BagFrameStats>::failure("every image topic needs its camera_info topic");
  std::map<std::string, std::string> info_of;  // image topic -> camera_info topic
  for (size_t i = 0; i < topics.image_topics.size(); ++i)
    info_of[topics.image_topics[i]] = topics.camera_info_topics[i];
  std::map<std::string, CameraIntrinsics> newest;  // camera_info topic -> newest intrinsics
  std::map<std::string, std::vector<ImageFrame>>
      waiting;  // image topic -> images before the first camera_info
  BagFrameStats stats;
  BagCallbacks cb;
  cb.on_camera_info = [&](const std::string& topic, const std::string&,
                          const CameraIntrinsics& in) {
    newest[topic] = in;
    for (auto& [image_topic, images] : waiting) {
      if (info_of[image_topic] != topic) continue;
      for (const auto& f : images)
        if (frames.on_image) frames.on_image(f, in);
      images.clear();
    }
  };
  cb.on_image = [&](const ImageFrame& f) {
    const auto in = newest.find(info_of[f.topic]);
    if (in != newest.end()) {
      if (frames.on_image) frames.on_image(f, in->second);
      return;
    }
    auto& held = waiting[f.topic];
    if (held.size() < kMaxImagesBeforeCameraInfo) {
      held.push_back(f);
      ++stats.images_before_info[f.topic];
    } else {
      ++stats.images_dropped[f.topic];
    }
  };
  cb.on_cloud = frames.on_cloud;
  cb.on_bad_message = frames.on_bad_message;
  const Status read = readBags(paths, topics, cb);
  if (!read) return Expected<BagFrameStats>::failure(read.reason);
  for (const auto& [topic, images] : waiting) stats.images_dropped[topic] += images.size();
  return stats;
}

}  // namespace board_calib
