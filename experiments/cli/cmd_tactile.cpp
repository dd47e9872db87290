// `touchstone simulate`, `touchstone log info`, `touchstone log export`: tactile logs;
// `touchstone log topics`, `touchstone log import`: what a ROS 2 recording (MCAP) holds, and the
// tactile log it makes.
#include "datasets/ros2_import.hpp"
#include "datasets/simulator.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/cli/cli_common.hpp"
#include "experiments/params/config.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/runs/grasp_pools.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/gripper_io.hpp"
#include "io/log_store.hpp"
#include "io/mcap.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>

namespace ts::cli {

namespace {
using ojson = nlohmann::ordered_json;

ojson tactile_pose_json(const Pose& T) {
  const Eigen::Quaterniond q(T.linear());
  const Vec3 t = T.translation();
  return {{"t", {t.x(), t.y(), t.z()}}, {"q", {q.w(), q.x(), q.y(), q.z()}}};
}

// ---- simulate -------------------------------------------------------------------------------
struct SimulateOptions {
  CommonOptions common;
  std::string db, object, out, gripper;
  std::size_t grasps = 40;
  /// The simulator parameters simulate takes (experiments/params/parameters.cpp: noise, sensors,
  /// sensing, the noise and probe overrides; --noise defaults to ideal here)
  experiments::ParameterFlags flags;
  std::vector<double> offset;
};

int run_simulate(const SimulateOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const io::DbReader db(o.db);
  const std::size_t index = db.find(o.object);
  if (index >= db.size()) {
    std::string names;
    for (std::size_t i = 0; i < db.size() && i < 8; ++i) names += (i ? ", " : "") + db.info(i).name;
    if (db.size() > 8) names += ", ...";
    throw Error("unknown object '" + o.object + "' (the database holds " + std::to_string(db.size()) +
                    " objects: " + names + ")",
                o.db, "--object");
  }
  const Gripper gripper = o.gripper.empty() ? Gripper() : io::read_gripper(o.gripper);
  // The simulator parameters as an experiment maps them (simulation_settings), from the flags.
  experiments::ExperimentConfig c;
  c.noise = "ideal";
  experiments::apply_flags(o.flags, c);
  datasets::SimulatorSettings s = experiments::simulation_settings(c);
  s.grasps = o.grasps;
  s.seed = o.common.seed;
  if (!o.offset.empty()) s.world_offset = Vec3(o.offset[0], o.offset[1], o.offset[2]);

  s.neighbours = datasets::scene_neighbours(s.scene, db.size(), index, s.seed, [&](std::size_t i) {
    return datasets::SceneObject{db.info(i).name, db.load_mesh(i)};
  });
  const datasets::Simulator sim(db.load_mesh(index), db.info(index).name, gripper, s);
  const datasets::SimulationResult result = sim.run();
  std::ostringstream source;
  source << "touchstone simulate --object " << o.object << " --grasps " << o.grasps << " --noise " << c.noise
         << " --sensors " << c.sensors << " --seed " << o.common.seed;
  if (s.sensing != Sensing::pads) source << " --sensing " << to_string(s.sensing);
  // The other simulator parameters given (the noise and probe overrides), as given, so that the
  // source reproduces the log.
  for (const experiments::Parameter& p : experiments::parameters()) {
    const auto it = o.flags.given.find(p.key);
    if (it == o.flags.given.end() || p.key == "noise" || p.key == "sensors" || p.key == "sensing") continue;
    source << ' ' << (p.aliases.empty() ? p.flag() : p.aliases.front()) << ' ' << it->second;
  }
  io::LogHeader header = io::header_of(result.log);
  header.source = source.str();
  io::LogWriter writer = io::LogWriter::create(o.out, header, true);
  for (std::size_t g = 0; g < result.log.grasps.size(); ++g)
    writer.append(result.log.grasps[g], &result.log.truth->arm_poses[g],
                  result.log.truth->joints.empty() ? nullptr : &result.log.truth->joints[g]);
  writer.close();

  std::size_t contacts = 0;
  for (std::size_t g = 0; g < result.log.grasps.size(); ++g) contacts += grasp_contacts(result.log, g).points.size();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (o.common.json) {
    ojson j;
    j["object"] = result.log.object;
    j["grasps"] = result.log.grasps.size();
    j["grasps_with_contact"] = result.grasps_with_contact;
    j["contacts"] = contacts;
    j["noise"] = s.noise.name;
    j["sensors"] = result.log.pads.size();
    j["sensing"] = to_string(result.log.sensing);
    j["seed"] = o.common.seed;
    j["out"] = o.out;
    j["time_s"] = seconds;
    std::cout << j.dump() << '\n';
  } else {
    std::cout << "simulated " << result.log.grasps.size()
              << (s.sensing == Sensing::probe ? " probe touches" : " grasps") << " on '" << result.log.object << "' ("
              << s.noise.name << ", "
              << (s.sensing == Sensing::probe        ? std::string("probe")
                  : s.sensing == Sensing::fingertips ? std::string("fingertips")
                  : std::to_string(result.log.pads.size()) + (result.log.pads.size() == 1 ? " pad" : " pads"))
              << "): " << result.grasps_with_contact << " with contact, " << contacts << " contact points -> "
              << o.out << " (" << std::fixed << std::setprecision(2) << seconds << " s)\n";
  }
  return 0;
}

// ---- log info -------------------------------------------------------------------------------
struct LogInfoOptions {
  CommonOptions common;
  std::string log;
};

int run_log_info(const LogInfoOptions& o) {
  const TactileLog log = io::read_log(o.log);
  std::vector<std::size_t> per_grasp;
  int ambiguous = 0;
  for (std::size_t g = 0; g < log.grasps.size(); ++g) {
    const GraspContacts c = grasp_contacts(log, g);
    per_grasp.push_back(c.points.size());
    ambiguous += c.ambiguous;
  }
  std::vector<std::string> pads;
  for (int p : log.pads) pads.push_back(log.gripper.pads()[p].name);
  const double duration = log.grasps.empty() ? 0.0 : log.grasps.back().time - log.grasps.front().time;
  if (o.common.json) {
    ojson j;
    j["object"] = log.object;
    j["grasps"] = log.grasps.size();
    j["contacts_per_grasp"] = per_grasp;
    j["ground_truth"] = log.truth ? tactile_pose_json(log.truth->object_pose) : ojson(nullptr);
    if (log.truth && !log.truth->support.faces.empty()) {
      j["scene"] = {{"kind", log.truth->scene}, {"support_faces", log.truth->support.faces.size()}};
      if (!log.truth->neighbours.empty()) {
        ojson n = ojson::array();
        for (const LogGroundTruth::Neighbour& x : log.truth->neighbours)
          n.push_back({{"object", x.name}, {"pose", tactile_pose_json(x.pose)}});
        j["scene"]["neighbours"] = n;
      }
    }
    j["noise"] = log.noise;
    j["sensors"] = log.pads.size();
    j["pads"] = pads;
    j["sensing"] = to_string(log.sensing);
    if (log.sensing == Sensing::probe)
      j["probe"] = {{"ball_radius_m", log.probe.ball_radius}, {"shaft_radius_m", log.probe.shaft_radius}};
    if (log.sensing == Sensing::fingertips) j["fingertip_normals"] = log.fingertip_normals;
    j["gripper"] = log.gripper.spec().name;
    j["seed"] = log.seed;
    j["duration_s"] = duration;
    j["ambiguous_sensels"] = ambiguous;
    std::cout << j.dump() << '\n';
    return 0;
  }
  std::size_t total = 0, with = 0;
  for (auto n : per_grasp) total += n, with += n > 0;
  std::cout << o.log << "\n"
            << "  object        " << (log.object.empty() ? "(unknown)" : log.object) << "\n"
            << "  noise         " << log.noise << "\n";
  if (log.sensing == Sensing::probe) {
    std::cout << "  sensing       probe, ball radius " << log.probe.ball_radius << " m";
  } else if (log.sensing == Sensing::fingertips) {
    std::cout << "  sensing       fingertips of " << log.gripper.spec().name << " (" << log.gripper.finger_count()
              << " fingers), " << (log.fingertip_normals ? "with normals" : "no normals");
  } else {
    std::cout << "  gripper       " << log.gripper.spec().name << ", pads logged:";
    for (const auto& p : pads) std::cout << ' ' << p;
  }
  std::cout << "\n  grasps        " << log.grasps.size() << " (" << with << " with contact, " << total
            << " contact points";
  if (ambiguous) std::cout << ", " << ambiguous << " sensels on an unknown side of the fold";
  std::cout << ")\n  ground truth  ";
  if (log.truth) {
    const auto j = tactile_pose_json(log.truth->object_pose);
    std::cout << "object at t = " << j["t"].dump() << ", q = " << j["q"].dump() << "\n";
    if (!log.truth->support.faces.empty())
      std::cout << "  scene         " << log.truth->scene << " (its support: " << log.truth->support.faces.size()
                << " faces, in the ground truth)\n";
    for (const LogGroundTruth::Neighbour& x : log.truth->neighbours)
      std::cout << "  neighbour     " << x.name << " at t = " << tactile_pose_json(x.pose)["t"].dump() << "\n";
  } else {
    std::cout << "none\n";
  }
  return 0;
}

// ---- log export -----------------------------------------------------------------------------
struct LogExportOptions {
  CommonOptions common;
  std::string log, out, free;
  std::size_t grasps = 0;          // 0: all
  bool ascii = false;
  ExplorationSettings exploration;
};

int run_log_export(const LogExportOptions& o) {
  const TactileLog log = io::read_log(o.log);
  const std::size_t k = o.grasps == 0 ? log.grasps.size() : std::min(o.grasps, log.grasps.size());
  const ExplorationClouds clouds = exploration_clouds(log, k, o.exploration);
  io::CloudWriteSettings ws;
  ws.encoding = o.ascii ? io::CloudEncoding::ascii : io::CloudEncoding::binary;
  io::write_cloud(o.out, clouds.contacts, ws);
  if (!o.free.empty()) io::write_cloud(o.free, clouds.free, ws);
  if (o.common.json) {
    ojson j;
    j["grasps"] = k;
    j["contacts"] = clouds.contacts.size();
    j["raw_contacts"] = clouds.raw_contacts;
    j["out"] = o.out;
    j["free_points"] = o.free.empty() ? ojson(nullptr) : ojson(clouds.free.size());
    j["free_out"] = o.free.empty() ? ojson(nullptr) : ojson(o.free);
    std::cout << j.dump() << '\n';
  } else {
    std::cout << "wrote " << clouds.contacts.size() << " contact points (" << clouds.raw_contacts
              << " before the voxel filter) of " << k << " grasps -> " << o.out << "\n";
    if (!o.free.empty()) std::cout << "wrote " << clouds.free.size() << " free-space points -> " << o.free << "\n";
  }
  return 0;
}
// ---- log topics ------------------------------------------------------------------------------
struct LogTopicsOptions {
  CommonOptions common;
  std::string recording;
};

/// The channels of an MCAP recording with their schemas and message counts (the whole data
/// section is read, so every checksum is checked too).
int run_log_topics(const LogTopicsOptions& o) {
  struct Topic {
    io::McapChannel channel;
    std::uint64_t messages = 0, bytes = 0, first = 0, last = 0;
  };
  io::McapHeader header;
  std::map<std::uint16_t, io::McapSchema> schemas;
  std::map<std::uint16_t, Topic> topics;
  io::McapHandlers h;
  h.header = [&](const io::McapHeader& x) { header = x; };
  h.schema = [&](const io::McapSchema& x) { schemas[x.id] = x; };
  h.channel = [&](const io::McapChannel& x) { topics[x.id].channel = x; };
  h.message = [&](const io::McapMessage& m) {
    Topic& t = topics[m.channel_id];
    t.first = t.messages ? std::min(t.first, m.log_time) : m.log_time;
    t.last = t.messages ? std::max(t.last, m.log_time) : m.log_time;
    ++t.messages;
    t.bytes += m.data.size();
  };
  const io::McapReadSummary s = io::read_mcap(o.recording, h);
  auto schema_of = [&](const Topic& t) -> std::pair<std::string, std::string> {
    const auto it = schemas.find(t.channel.schema_id);
    if (it == schemas.end()) return {"", ""};
    return {it->second.name, it->second.encoding};
  };
  if (o.common.json) {
    ojson j;
    j["recording"] = o.recording;
    j["profile"] = header.profile;
    j["library"] = header.library;
    j["chunks"] = s.chunks;
    j["messages"] = s.messages;
    j["data_section_crc_checked"] = s.data_section_crc != 0;
    j["topics"] = ojson::array();
    for (const auto& [id, t] : topics) {
      const auto [name, encoding] = schema_of(t);
      j["topics"].push_back({{"channel", id}, {"topic", t.channel.topic}, {"message_encoding", t.channel.message_encoding},
                             {"schema", name}, {"schema_encoding", encoding}, {"messages", t.messages},
                             {"bytes", t.bytes}, {"first_log_time_ns", t.first}, {"last_log_time_ns", t.last}});
    }
    std::cout << j.dump(2) << '\n';
    return 0;
  }
  std::cout << o.recording << ": MCAP, profile '" << header.profile << "', library '" << header.library << "', "
            << s.messages << " messages in " << s.chunks << " chunks"
            << (s.data_section_crc ? ", data CRC checked" : "") << "\n";
  std::cout << std::left << std::setw(28) << "topic" << std::setw(40) << "schema" << std::right << std::setw(10)
            << "messages" << std::setw(12) << "seconds" << "\n";
  for (const auto& [id, t] : topics) {
    const auto [name, encoding] = schema_of(t);
    std::cout << std::left << std::setw(28) << t.channel.topic << std::setw(40)
              << (name.empty() ? "(none)" : name + " (" + encoding + ")") << std::right << std::setw(10) << t.messages
              << std::setw(12) << std::fixed << std::setprecision(3) << 1e-9 * static_cast<double>(t.last - t.first)
              << "\n";
  }
  return 0;
}
// ---- log import ------------------------------------------------------------------------------
struct LogImportOptions {
  CommonOptions common;
  std::string recording, map, out;
};

int run_log_import(const LogImportOptions& o) {
  const datasets::Ros2Map map = datasets::read_ros2_map(o.map);
  datasets::Ros2ImportReport rep;
  const TactileLog log = datasets::import_ros2(o.recording, map, o.map, &rep);
  io::LogHeader header = io::header_of(log);
  header.source = "touchstone log import " + o.recording + " --map " + o.map;
  io::LogWriter writer = io::LogWriter::create(o.out, header, true);
  for (const GraspRecord& g : log.grasps) writer.append(g);
  writer.close();
  if (o.common.json) {
    ojson j;
    j["recording"] = o.recording;
    j["out"] = o.out;
    j["grasps"] = rep.grasps;
    j["arm_messages"] = rep.arm_messages;
    j["joint_messages"] = rep.joint_messages;
    j["largest_skew_s"] = rep.largest_skew_s;
    std::cout << j.dump() << '\n';
  } else {
    std::cout << "imported " << rep.grasps << " grasps (" << rep.arm_messages << " arm poses, " << rep.joint_messages
              << " joint states; largest time skew " << std::fixed << std::setprecision(3) << rep.largest_skew_s
              << " s) -> " << o.out << "\n";
  }
  return 0;
}
}  // namespace

void register_tactile(CLI::App& app) {
  // simulate
  {
    auto opt = std::make_shared<SimulateOptions>();
    CLI::App* sub = app.add_subcommand("simulate", "Simulate random grasps on a database object; write a tactile log");
    sub->add_option("--db", opt->db, "Object database (HDF5)")->required();
    sub->add_option("--object", opt->object, "Name of the object to explore")->required();
    sub->add_option("--grasps", opt->grasps, "Number of grasps")->required()->check(CLI::Range(1, 1000000));
    sub->add_option("--out", opt->out, "Tactile log to write (HDF5)")->required();
    // --noise (default ideal here), --sensors, --sensing, --arm-position-sigma, --arm-rotation-sigma,
    // --signal-noise, --force-noise, --joint-sigma, --lateral-sigma / --contact-sigma (one key,
    // noise.contact_sigma_m: a sensel's lateral error, or the probe's own noise), --ball-radius,
    // --probe-tilt, --quantization: the simulator parameters of experiments/params/parameters.cpp.
    experiments::add_parameter_flags(*sub, opt->flags, "Simulator parameters (touchstone params)",
                                     [](const experiments::Parameter& p) { return p.simulate; });
    sub->add_option("--gripper", opt->gripper, "Gripper description (JSON; default: the built-in touchstone-3f)");
    sub->add_option("--offset", opt->offset, "X Y Z: world position of the object (m; e.g. a dive site far from the origin)")
        ->expected(3);
    add_common(sub, opt->common);
    sub->callback([opt] { run_command(opt->common, [opt] { return run_simulate(*opt); }); });
  }
  // log info | export
  CLI::App* log = app.add_subcommand("log", "Inspect and export tactile logs; list what a ROS 2 recording holds");
  log->require_subcommand(1);
  {
    auto opt = std::make_shared<LogInfoOptions>();
    CLI::App* sub = log->add_subcommand("info", "Summary of a tactile log");
    sub->add_option("log,--log", opt->log, "Tactile log (HDF5)")->required();
    add_common(sub, opt->common, kJson);
    sub->callback([opt] { run_command(opt->common, [opt] { return run_log_info(*opt); }); });
  }
  {
    auto opt = std::make_shared<LogTopicsOptions>();
    CLI::App* sub = log->add_subcommand("topics", "Channels of a ROS 2 recording (MCAP): topics, schemas, message counts");
    sub->add_option("recording,--recording", opt->recording, "Recording (.mcap; chunks plain, lz4 or zstd)")->required();
    add_common(sub, opt->common, kJson);
    sub->callback([opt] { run_command(opt->common, [opt] { return run_log_topics(*opt); }); });
  }
  {
    auto opt = std::make_shared<LogImportOptions>();
    CLI::App* sub = log->add_subcommand("import", "A tactile log from a ROS 2 recording (MCAP): one grasp per tactile "
                                                  "message, the arm pose and joints nearest in time");
    sub->add_option("recording,--recording", opt->recording, "Recording (.mcap)")->required();
    sub->add_option("--map", opt->map, "Which topics hold the arm pose, the joints and the tactile images (TOML; "
                                        "docs/logs-and-simulator.md, ROS 2 recordings)")->required();
    sub->add_option("--out", opt->out, "Tactile log to write (HDF5)")->required();
    add_common(sub, opt->common, kThreads | kJson);
    sub->callback([opt] { run_command(opt->common, [opt] { return run_log_import(*opt); }); });
  }
  {
    auto opt = std::make_shared<LogExportOptions>();
    CLI::App* sub = log->add_subcommand("export", "Cumulative contact cloud (and free space) as PLY/PCD");
    sub->add_option("log,--log", opt->log, "Tactile log (HDF5)")->required();
    sub->add_option("--out", opt->out, "Contact cloud to write (.ply or .pcd)")->required();
    sub->add_option("--grasps", opt->grasps, "Use the first K grasps (default: all)")->check(CLI::PositiveNumber);
    sub->add_option("--free", opt->free, "Also write the free-space cloud of Eq. 3 (.ply or .pcd)");
    sub->add_flag("--ascii", opt->ascii, "Write ASCII instead of binary");
    auto fs = "Fusion parameters";
    sub->add_option("--voxel", opt->exploration.contact_voxel, "m, voxel filter of the contact cloud")
        ->group(fs)->check(CLI::PositiveNumber)->capture_default_str();
    sub->add_option("--res-free", opt->exploration.free.res_free, "m, free-space sampling")
        ->group(fs)->check(CLI::PositiveNumber)->capture_default_str();
    sub->add_option("--s-obj-max", opt->exploration.free.s_obj_max, "m, largest object (box B of Eq. 3)")
        ->group(fs)->check(CLI::NonNegativeNumber)->capture_default_str();
    sub->add_option("--occupancy-voxel", opt->exploration.free.voxel, "m, occupancy grid voxel")
        ->group(fs)->check(CLI::PositiveNumber)->capture_default_str();
    add_common(sub, opt->common, kThreads | kJson);
    sub->callback([opt] { run_command(opt->common, [opt] { return run_log_export(*opt); }); });
  }
}

}  // namespace ts::cli
