// Gripper description files (JSON). The format, with units in every key name:
//
//   {
//     "format": "touchstone-gripper", "version": 1, "name": "touchstone-3f",
//     "palm": {"radius_m": 0.06, "thickness_m": 0.03},
//     "single_pad": "middle.distal",                  // the pad of `--sensors 1`
//     "sensor": {"rows": 12, "cols": 6, "pitch_m": [0.005, 0.005], "size_m": [0.06, 0.03],
//                "foam_thickness_m": 0.004,
//                "response": {"knee": 0.6, "peak": 0.8, "end": 0.6},
//                "signal_peak": 200, "signal_full_scale": 255, "threshold": 0.1},
//     "fingers": [
//       {"name": "middle", "base": {"t_m": [0.05, 0, 0], "rpy_deg": [0, 0, 0]},
//        "links": [
//          {"name": "proximal", "length_m": 0.075, "width_m": 0.035, "thickness_m": 0.02,
//           "joint": {"origin_m": [0, 0, 0], "axis": [0, -1, 0],
//                     "open_deg": -25, "min_deg": -30, "max_deg": 100},
//           "pad": {"t_m": [-0.01, 0, 0.0375], "rpy_deg": [0, -90, 0]}},     // or null: no pad
//          ...]},
//       ...]
//   }
//
// Frames and conventions: see engine/touch/gripper.hpp. rpy_deg = [roll, pitch, yaw] with
// R = Rz(yaw) Ry(pitch) Rx(roll); "q_wxyz": [w, x, y, z] is accepted instead of rpy_deg.
// "palm", "sensor", "single_pad" and each joint's "origin_m" (default: the parent link's tip,
// (0, 0, parent length)) are optional; everything else is required.
// datasets/grippers/touchstone-3f.json is the compiled-in default (ts::default_gripper_spec()).
#pragma once

#include "engine/touch/gripper.hpp"

#include <filesystem>
#include <string>

namespace ts::io {

/// Parse a description; throws ts::Error naming `file` and the JSON field (or the byte
/// offset of a syntax error). The result is validated (ts::Gripper's checks).
Gripper parse_gripper(const std::string& json_text, const std::string& file = {});
Gripper read_gripper(const std::filesystem::path& path);
/// Serialize (pretty JSON, degrees); parse_gripper(gripper_to_json(g)) reproduces g.
std::string gripper_to_json(const GripperSpec& spec);

}  // namespace ts::io
