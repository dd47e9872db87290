#include "datasets/ros2_import.hpp"

#include "io/gripper_io.hpp"
#include "io/mcap.hpp"
#include "io/ros2_messages.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <set>

namespace ts::datasets {

namespace {

double number(const std::vector<std::string>& inputs, const std::string& file, const std::string& key) {
  if (inputs.size() != 1) throw Error("expects one number", file, key);
  char* end = nullptr;
  const double v = std::strtod(inputs[0].c_str(), &end);
  if (end == inputs[0].c_str() || *end != '\0' || !std::isfinite(v))
    throw Error("'" + inputs[0] + "' is not a number", file, key);
  return v;
}

std::string text(const std::vector<std::string>& inputs, const std::string& file, const std::string& key) {
  if (inputs.size() != 1) throw Error("expects one string", file, key);
  return inputs[0];
}

/// Samples of one topic by log time.
template <class T>
struct Series {
  std::vector<std::uint64_t> t;
  std::vector<T> v;
  /// The sample nearest to `time` and its distance in seconds (the earlier one on a tie).
  std::pair<const T*, double> nearest(std::uint64_t time) const {
    if (t.empty()) return {nullptr, INFINITY};
    const auto it = std::lower_bound(t.begin(), t.end(), time);
    std::size_t best = static_cast<std::size_t>(it - t.begin());
    if (best == t.size() || (best > 0 && time - t[best - 1] <= t[best] - time)) best = best == 0 ? 0 : best - 1;
    const double d = 1e-9 * static_cast<double>(t[best] > time ? t[best] - time : time - t[best]);
    return {&v[best], d};
  }
};

}  // namespace

Ros2Map read_ros2_map(const std::filesystem::path& path) {
  const std::string file = path.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error("cannot read the map file", file);
  std::vector<CLI::ConfigItem> items;
  try {
    CLI::ConfigTOML parser;
    items = parser.from_file(file);
  } catch (const CLI::Error& e) {
    throw Error(std::string("cannot parse the map file: ") + e.what(), file);
  }
  Ros2Map m;
  std::set<std::string> seen;
  for (const auto& item : items) {
    if (item.name == "++" || item.name == "--") continue;   // CLI11's section markers
    const std::string key = item.fullname();
    if (!seen.insert(key).second) throw Error("key given twice", file, key);
    const auto& in = item.inputs;
    if (key == "object") m.object = text(in, file, key);
    else if (key == "gripper") {
      const std::string g = text(in, file, key);
      m.gripper = g.empty() ? std::filesystem::path() : (path.parent_path() / g);
    } else if (key == "pads") m.pads = in;
    else if (key == "max_skew_s") {
      m.max_skew_s = number(in, file, key);
      if (!(m.max_skew_s > 0.0 && m.max_skew_s <= 3600.0)) throw Error("must lie in (0, 3600] s", file, key);
    } else if (key == "arm.topic") m.arm_topic = text(in, file, key);
    else if (key == "arm.parent") m.arm_parent = text(in, file, key);
    else if (key == "arm.child") m.arm_child = text(in, file, key);
    else if (key == "joints.topic") m.joints_topic = text(in, file, key);
    else if (key == "joints.names") m.joint_names = in;
    else if (key == "joints.unit") {
      const std::string u = text(in, file, key);
      if (u != "rad" && u != "deg") throw Error("'" + u + "' is not rad or deg", file, key);
      m.joints_in_degrees = u == "deg";
    } else if (key == "tactile.topic") m.tactile_topic = text(in, file, key);
    else
      throw Error("unknown key (object, gripper, pads, max_skew_s, arm.topic, arm.parent, arm.child, joints.topic, "
                  "joints.names, joints.unit, tactile.topic)", file, key);
  }
  for (const auto& [key, value] : {std::pair{"arm.topic", &m.arm_topic}, {"joints.topic", &m.joints_topic},
                                   {"tactile.topic", &m.tactile_topic}})
    if (value->empty()) throw Error("missing: the map must name this topic", file, key);
  if (m.arm_parent.empty() != m.arm_child.empty())
    throw Error("give both arm.parent and arm.child (a TFMessage topic), or neither", file,
                m.arm_parent.empty() ? "arm.parent" : "arm.child");
  return m;
}

TactileLog import_ros2(const std::filesystem::path& recording, const Ros2Map& map, const std::string& map_file,
                       Ros2ImportReport* report) {
  const std::string file = recording.string();
  TactileLog log;
  log.object = map.object;
  log.noise = "real";
  log.gripper = map.gripper.empty() ? Gripper() : io::read_gripper(map.gripper);
  const Gripper& G = log.gripper;
  if (map.pads.empty()) {
    log.pads = {G.single_pad()};
  } else {
    for (const std::string& name : map.pads) {
      const int p = G.pad_index(name);
      if (p < 0) throw Error("the gripper has no pad '" + name + "'", map_file, "pads");
      if (std::find(log.pads.begin(), log.pads.end(), p) != log.pads.end())
        throw Error("pad '" + name + "' given twice", map_file, "pads");
      log.pads.push_back(p);
    }
  }
  const std::size_t sensels = log.sensels();
  log.gains.assign(log.pads.size() * sensels, 1.0f);
  // The joints in the gripper's order: their names in the recording.
  std::vector<std::string> names = map.joint_names;
  if (names.empty())
    for (int j = 0; j < G.joint_count(); ++j)
      names.push_back(G.spec().fingers[static_cast<std::size_t>(G.finger_of_joint(j))].name + "." + G.link(j).name);
  if (static_cast<int>(names.size()) != G.joint_count())
    throw Error(std::to_string(names.size()) + " joint names for a gripper of " + std::to_string(G.joint_count()) +
                    " joints", map_file, "joints.names");

  // The channels of the three topics, checked against the message types they must carry.
  std::map<std::uint16_t, std::string> schema_names;
  std::map<std::uint16_t, int> role;   // channel -> 0 arm, 1 joints, 2 tactile
  std::map<int, std::uint64_t> counts;
  Series<Pose> arm;
  Series<std::vector<double>> joints;
  std::vector<std::pair<std::uint64_t, std::vector<float>>> images;
  const bool tf = !map.arm_parent.empty();
  const std::string topics[3] = {map.arm_topic, map.joints_topic, map.tactile_topic};
  const std::string types[3] = {tf ? "tf2_msgs/msg/TFMessage" : "geometry_msgs/msg/PoseStamped",
                                "sensor_msgs/msg/JointState", "std_msgs/msg/Float32MultiArray"};
  const char* keys[3] = {"arm.topic", "joints.topic", "tactile.topic"};
  io::McapHandlers h;
  h.schema = [&](const io::McapSchema& s) { schema_names[s.id] = s.name; };
  h.channel = [&](const io::McapChannel& c) {
    for (int r = 0; r < 3; ++r) {
      if (c.topic != topics[r]) continue;
      const auto it = schema_names.find(c.schema_id);
      const std::string type = it == schema_names.end() ? "(no schema)" : it->second;
      if (type != types[r] && type != types[r].substr(0, types[r].find("/msg/")) + types[r].substr(types[r].find("/msg/") + 4))
        throw Error("topic " + c.topic + " carries " + type + ", not " + types[r], map_file, keys[r]);
      if (c.message_encoding != "cdr")
        throw Error("topic " + c.topic + " is encoded as '" + c.message_encoding + "', not cdr", file, keys[r]);
      role[c.id] = r;
    }
  };
  h.message = [&](const io::McapMessage& m) {
    const auto it = role.find(m.channel_id);
    if (it == role.end()) return;
    const int r = it->second;
    const std::string what = "message " + std::to_string(++counts[r]) + " on " + topics[r];
    auto add = [&](auto& series, auto value) {
      if (!series.t.empty() && m.log_time < series.t.back())
        throw Error("log times go backwards", file, what);
      series.t.push_back(m.log_time);
      series.v.push_back(std::move(value));
    };
    if (r == 0 && !tf) {
      add(arm, io::ros2::decode_pose_stamped(m.data, file, what).pose);
    } else if (r == 0) {
      for (const auto& t : io::ros2::decode_tf_message(m.data, file, what))
        if (t.frame_id == map.arm_parent && t.child_frame_id == map.arm_child) add(arm, t.transform);
    } else if (r == 1) {
      const io::ros2::JointState js = io::ros2::decode_joint_state(m.data, file, what);
      if (js.position.size() != js.name.size())
        throw Error(std::to_string(js.name.size()) + " names but " + std::to_string(js.position.size()) + " positions",
                    file, what + ": position");
      std::vector<double> q(names.size());
      for (std::size_t j = 0; j < names.size(); ++j) {
        const auto at = std::find(js.name.begin(), js.name.end(), names[j]);
        if (at == js.name.end()) throw Error("no joint '" + names[j] + "' (joints.names of " + map_file + ")", file, what + ": name");
        q[j] = js.position[static_cast<std::size_t>(at - js.name.begin())] * (map.joints_in_degrees ? std::numbers::pi / 180.0 : 1.0);
      }
      add(joints, std::move(q));
    } else {
      io::ros2::Float32MultiArray a = io::ros2::decode_float32_multi_array(m.data, file, what);
      if (a.data.size() != log.pads.size() * sensels)
        throw Error(std::to_string(a.data.size()) + " values, not the " + std::to_string(log.pads.size()) + " pads x " +
                        std::to_string(sensels) + " sensels the map and the gripper give", file, what + ": data");
      if (!images.empty() && m.log_time < images.back().first) throw Error("log times go backwards", file, what);
      images.emplace_back(m.log_time, std::move(a.data));
    }
  };
  (void)io::read_mcap(recording, h);
  for (int r = 0; r < 3; ++r)
    if (!std::any_of(role.begin(), role.end(), [&](const auto& kv) { return kv.second == r; }))
      throw Error("the recording has no topic " + topics[r], file, keys[r]);
  if (images.empty()) throw Error("no message on the tactile topic " + map.tactile_topic, file, "tactile.topic");
  if (arm.t.empty())
    throw Error(tf ? "no transform " + map.arm_parent + " -> " + map.arm_child + " on " + map.arm_topic
                   : "no message on " + map.arm_topic, file, "arm.topic");

  Ros2ImportReport rep;
  rep.arm_messages = arm.t.size();
  rep.joint_messages = joints.t.size();
  for (std::size_t g = 0; g < images.size(); ++g) {
    const std::uint64_t t = images[g].first;
    const std::string what = "grasp " + std::to_string(g + 1) + " (message " + std::to_string(g + 1) + " on " +
                             map.tactile_topic + ")";
    const auto [pose, arm_skew] = arm.nearest(t);
    const auto [q, joint_skew] = joints.nearest(t);
    for (const auto& [skew, topic] : {std::pair{arm_skew, map.arm_topic}, {joint_skew, map.joints_topic}})
      if (!(skew <= map.max_skew_s))
        throw Error("the nearest message on " + topic + " is " + std::to_string(skew) + " s away (max_skew_s " +
                        std::to_string(map.max_skew_s) + " in " + map_file + ")", file, what);
    rep.largest_skew_s = std::max({rep.largest_skew_s, arm_skew, joint_skew});
    GraspRecord rec;
    rec.time = 1e-9 * static_cast<double>(t);
    rec.arm_pose = *pose;
    rec.joints = *q;
    rec.tactile = std::move(images[g].second);
    try {
      validate_grasp(log, rec, g, file);
    } catch (const Error& e) {
      throw Error(e.message(), file, what + (e.field().empty() ? "" : ": " + e.field()));
    }
    log.grasps.push_back(std::move(rec));
  }
  rep.grasps = log.grasps.size();
  if (report) *report = rep;
  return log;
}

}  // namespace ts::datasets
