// `touchstone params`: every parameter (method, simulator, experiment) as declared in
// experiments/params/parameters.cpp (key, kind, flag and older names, the commands taking the flag,
// type, unit, range, each preset's value, the paper's value, help).
#include "experiments/cli/cli_common.hpp"
#include "experiments/params/parameters.hpp"

#include <iostream>

namespace ts::cli {

void register_params(CLI::App& app) {
  struct Options {
    CommonOptions common;
    std::string preset;
    bool markdown = false;
  };
  auto o = std::make_shared<Options>();
  auto* sub = app.add_subcommand(
      "params", "List every parameter (method, simulator, experiment): its key (experiment keys and --set), "
                "its flag and the commands taking it, unit, range, the presets' values and the paper's");
  sub->add_option("--preset", o->preset, "Only this preset's values: paper | improved (default: both)")
      ->check(CLI::IsMember({"paper", "improved"}));
  auto* md = sub->add_flag("--markdown", o->markdown, "The parameter table of docs/parameters.md (Markdown)");
  add_common(sub, o->common, kJson);   // no random draws, no parallel work
  md->excludes("--json");
  sub->callback([o] {
    run_command(o->common, [o] {
      if (o->markdown) {
        std::cout << experiments::parameters_markdown();
        return 0;
      }
      const nlohmann::ordered_json j = experiments::parameters_json(o->preset);
      if (o->common.json) {
        nlohmann::ordered_json out;
        out["preset"] = o->preset.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(o->preset);
        out["parameters"] = j;
        std::cout << out.dump(2) << '\n';
        return 0;
      }
      for (const char* kind : {"method", "simulator", "experiment"}) {
       std::cout << kind << " parameters:\n";
       for (const auto& p : j) {
        if (p["kind"] != kind) continue;
        std::cout << p["key"].get<std::string>() << "  " << p["flag"].get<std::string>();
        const std::string unit = p["unit"].get<std::string>();
        if (!unit.empty()) std::cout << "  [" << unit << "]";
        std::cout << "\n    " << p["help"].get<std::string>() << "\n    default " << p["default"].dump();
        if (!p["paper"].is_null()) std::cout << "; paper " << p["paper"].get<std::string>();
        if (!p["aliases"].empty()) std::cout << "; also " << p["aliases"].dump();
        std::cout << '\n';
       }
      }
      return 0;
    });
  });
}

}  // namespace ts::cli
