// Reports of an experiment: metrics per step (all objects and per object), per sweep variant,
// and the Pareto front of recognition / pose error against time per step. Produces the JSON of
// the interface contract (shared by `experiment --json` and `report --json`), terminal tables,
// and runs the plot script.
#pragma once

#include "experiments/analysis/metrics.hpp"
#include "io/run_store.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <iosfwd>
#include <map>
#include <set>
#include <string>

namespace ts::experiments {

struct Calibration;

struct ReportSettings {
  ErrorBounds bounds;          ///< the paper's 4 cm / 1 rad
  /// Recompute the confidences from the store's features with this model (e.g. one fitted on
  /// other runs); null: the confidences the store recorded (if any).
  const Calibration* calibration = nullptr;
  std::string calibration_path;  ///< reported as the confidences' source
  int threads = 0;             ///< reported "threads" (the experiment's); 0: from the store
  std::string machine;         ///< reported "machine"; empty: from the store
};

/// The report JSON: {"config", "store", "per_step", "per_object", "variants", "pareto",
/// "threads", "machine"}. per_step / per_object describe the first variant (the only one
/// without a sweep); "variants" repeats them for every variant of a sweep.
/// Orientation errors are in degrees, positions in metres; undefined values are null.
/// Recognition rates come strict ("recognition_rate": the explored object itself) and
/// class-aware ("recognition_rate_class": an object congruent with it counts too, by the classes
/// the store's database recorded, "congruent_classes"; null: none known, the two agree).
nlohmann::ordered_json report_json(const io::RunStoreContents& store, const ReportSettings& settings,
                                   const std::string& store_path = {});

/// The explored objects (indices into the header's objects) that the runs hid from the
/// recognizer (config `hidden`; "each": all of them): open-set runs.
std::set<int> hidden_explored_objects(const io::RunStoreHeader& header);

/// Classes of congruent objects of the store's database (header database_json
/// "congruent_classes", names): object name -> class number. Empty when none are known.
using ClassMap = std::map<std::string, std::size_t>;
ClassMap class_map(const io::RunStoreHeader& header);

/// The step's answer lies in the explored object's class (strictly right answers included; with
/// no classes known, the strict outcome). For a run of a hidden object: its answer names a copy
/// of it that is in the database.
bool correct_in_class(const io::RunStoreHeader& header, const io::RunRecord& run, const io::RunStepRecord& step,
                      const ClassMap& classes);

/// Human tables (recognition and errors per step, per object at a few steps, sweep variants and
/// the Pareto front) written to `out`.
void print_report(const nlohmann::ordered_json& report, std::ostream& out);

/// Write `report` to DIR/`json_name` (a report, or {"scenes": [...]} of experiments/analysis/scene.hpp)
/// and run the plot script (/usr/bin/python3, or $TOUCHSTONE_PYTHON) on it, which writes
/// DIR/*.png (and a scene's .html). Throws ts::Error when the script cannot be found or fails.
/// Returns the files written.
std::vector<std::filesystem::path> write_plots(const nlohmann::ordered_json& report,
                                               const std::filesystem::path& dir,
                                               const std::string& json_name = "report.json");

/// Where the plot script is: $TOUCHSTONE_PLOT_SCRIPT, else scripts/plots/touchstone_plots.py
/// beside the executable's source tree (../scripts from the build folder, or the source
/// folder this binary was built from).
std::filesystem::path plot_script();

}  // namespace ts::experiments
