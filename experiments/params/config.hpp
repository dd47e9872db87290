// Experiment configuration: objects x runs x steps x method x noise x sensors, the method's
// cost knobs, and an optional sweep (a grid of variants). Read from a TOML/INI file (CLI11's
// config parser) and/or command-line flags; every key goes through one setter, so a file key
// and a flag are validated alike and an error names the key (and the file).
//
// Keys (file sections become dotted prefixes: `[ransac]` + `triplets = 15` is ransac.triplets):
// every parameter of experiments/params/parameters.cpp, method, simulator and experiment alike
// (`touchstone params`, and the tables of docs/parameters.md): objects, runs, steps, pool, protocol, noise,
// sensors, seed, ransac.triplets, bricpsf.psi, ...; a method parameter unset means the preset's
// value. `sweep.<key> = [v1, v2, ...]` (sweepable keys only): one variant per combination
// (cartesian product, the first listed key varies slowest).
#pragma once

#include "engine/core.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace ts::experiments {

/// Overrides of the simulator's noise profile (unset: the profile's value).
struct NoiseOverrides {
  std::optional<double> arm_position_sigma_m;    ///< m per axis, per grasp
  std::optional<double> arm_rotation_sigma_deg;  ///< deg, per grasp
  std::optional<double> arm_scale;               ///< times both arm errors (0: none; sweeps the error's size)
  std::optional<double> sensel_noise;            ///< fraction of the signal (0.05 = 5 %)
  std::optional<double> force_noise;             ///< fraction of the force (deep sea: 0.5)
  std::optional<double> contact_sigma_m;         ///< m, contact position noise (Q = diag)
  std::optional<double> joint_sigma_deg;         ///< deg, finger joint readings
};

/// Overrides of the simulated touch probe (sensing = "probe"; unset: the simulator's default).
struct ProbeOverrides {
  std::optional<double> ball_radius_m;           ///< m, ball-tip radius
  std::optional<double> tilt_deg;                ///< deg, approach cone about the surface normal
  std::optional<double> quantization_m;          ///< m, recorded positions rounded to this
};

/// Overrides of the simulated fingertip hand (sensing = "fingertips"; unset: the simulator's
/// default).
struct FingertipOverrides {
  std::optional<double> quantization_m;          ///< m, reported coordinates rounded to this
  std::optional<double> normals_deg;             ///< deg, normal noise; unset: no normals
};

/// Overrides of the simulated scene (scene = "seabed", "panel", "pipe" or "cluttered"; unset:
/// datasets::SceneSettings' default).
struct SceneOverrides {
  std::optional<double> slope_deg;               ///< deg, the support's tilt
  std::optional<double> relief_m;                ///< m, sediment relief amplitude
  std::optional<double> relief_wavelength_m;     ///< m, the relief's wavelength
  std::optional<double> gap_m;                   ///< m, the object's lowest point above the support
  std::optional<double> off_target;              ///< share of grasps aimed at the support
  std::optional<double> off_target_radius_m;     ///< m, how far from the object those aim
  std::optional<double> extent_m;                ///< m, half-size of the support patch
  std::optional<double> pipe_radius_m;           ///< m, a pipe's radius (scene = pipe)
  std::optional<int> neighbours;                 ///< cluttered: database objects beside the object
  std::optional<double> neighbour_distance_m;    ///< m, cluttered: their distance from it
  std::optional<double> neighbour_share;         ///< cluttered: share of off-target aims at them
};

struct SweepAxis {
  std::string key;                              ///< a scalar key, e.g. "ransac.samples"
  std::vector<std::vector<std::string>> values; ///< one entry per variant value (a key's inputs)
};

struct ExperimentConfig {
  std::string name = "experiment";
  std::string description;
  std::vector<std::string> objects;     ///< explored objects; empty = all of the database
  std::vector<std::string> database;    ///< objects the recognizer knows; empty = all
  std::optional<int> database_size;     ///< truncate the database (explored objects first)
  std::vector<std::string> hidden;      ///< open set: hidden from the recognizer; {"each"}:
                                        ///< every explored object from its own runs
  int runs = 20;
  int steps = 40;
  int pool = 50;
  /// "independent" (each run its own object pose and grasp pool) | "shared_pool" (the paper's
  /// protocol: one pose and pool per object, shared by its runs)
  std::string protocol = "independent";
  std::string method = "bricpsf";
  std::string preset = "improved";      ///< paper | improved: the defaults the params start from
  std::string noise = "underwater";
  NoiseOverrides noise_params;
  ProbeOverrides probe_params;
  FingertipOverrides fingertip_params;
  std::string scene = "none";           ///< none | seabed | panel | pipe | cluttered (datasets::SceneSettings)
  SceneOverrides scene_params;
  int sensors = 1;
  std::string sensing = "pads";         ///< pads | probe (datasets::ProbeSettings) | fingertips
                                        ///< (datasets::FingertipSettings)
  std::uint64_t seed = 1;
  /// Method parameters set explicitly (key of experiments/params/parameters.hpp -> value; unset: the
  /// preset's)
  std::map<std::string, double> params;
  std::string schedule = "runs";
  std::string calibration;              ///< confidence calibration file; "": none
  std::optional<double> memory_budget_mb;  ///< resident object geometry (MB); unset: the default
  std::vector<SweepAxis> sweep;
};

/// Every key the configuration accepts (without the sweep. prefix), in documentation order.
const std::vector<std::string>& config_keys();

/// Set one key from its textual inputs (a config item's or a flag's). Throws ts::Error naming
/// `key` (and `file` when given) on an unknown key or an impossible value.
void set_key(ExperimentConfig& config, const std::string& key,
             const std::vector<std::string>& inputs, const std::string& file = {});

/// Read a TOML or INI file (CLI11's parser) on top of `config`. Unknown keys, impossible values
/// and unreadable files throw ts::Error naming the file and the key.
void load_config_file(ExperimentConfig& config, const std::filesystem::path& file);

/// Checks that need all keys together (pool >= steps, sweep values valid, check_memory with the
/// explored objects listed, or one for all). Throws ts::Error naming the key.
void validate(const ExperimentConfig& config, const std::string& file = {});
/// The scene keys' part of validate: a cluttered scene's keys given for another scene (scene
/// none ignores every scene.* key) are refused (also checked by simulation_settings, for the
/// simulator's other callers).
void check_scene_keys(const ExperimentConfig& config, const std::string& file = {});

/// Checks, from the configuration alone and before anything runs or is written, that what an
/// experiment holds in memory at once can fit in `memory_bytes` (0: this machine's physical
/// memory). Lower bounds, each a product of keys times the bytes of one element:
///   - the run store's step records, variants (the sweep) x `explored_objects` x runs x steps
///     (the report and --resume read them all);
///   - a grasp pool: pool grasps (one run's, or one explored object's with shared_pool);
///   - a step's RANSAC registrations: ransac.triplets x ransac.registrations slots, per variant.
/// Throws ts::Error naming `file` and the key: the product's largest factor (runs, steps,
/// sweep, objects), pool, ransac.samples (sweep.KEY when the sweep sets it).
void check_memory(const ExperimentConfig& config, std::size_t explored_objects, const std::string& file = {},
                  double memory_bytes = 0.0);

/// Resolve explored and database objects against the database's names: "all" expands, unknown
/// names throw ts::Error naming the key ("objects" or "database") and the name.
struct ResolvedObjects {
  std::vector<std::string> explored;   ///< in the configuration's order
  std::vector<std::string> database;   ///< what the recognizer knows, explored objects first
                                       ///< (hidden objects excluded)
  std::vector<std::string> hidden;     ///< explored objects the recognizer does not know
  bool hide_each = false;              ///< hidden = "each": each explored object from its runs
  bool known_each = false;             ///< database = "each": each run may name only its object
                                       ///< (known-object localization, `recognize --only`)
};
ResolvedObjects resolve_objects(const ExperimentConfig& config,
                                const std::vector<std::string>& database_names);

/// One combination of the sweep (or the configuration itself when there is no sweep).
struct Variant {
  std::string label;                   ///< "ransac.samples=15x200, method=bricpsf"; "" if none
  ExperimentConfig config;             ///< with the sweep applied and cleared
};
std::vector<Variant> expand_variants(const ExperimentConfig& config);

/// Canonical JSON of everything that determines results (all keys, unset ones as null; the
/// schedule is informative and kept apart under "schedule").
nlohmann::ordered_json to_json(const ExperimentConfig& config);

/// Compare two canonical configurations; returns the first key whose value differs ("" when
/// they determine the same results; "schedule" is ignored; a key absent on one side counts as
/// unset, null).
std::string first_difference(const nlohmann::ordered_json& a, const nlohmann::ordered_json& b);

}  // namespace ts::experiments
