// `touchstone --help-reference`: the whole command line as one JSON object, read from the parsed
// CLI11 tree itself (every subcommand, its positionals and flags, their types, defaults and
// help), for scripts/command_reference.py, which writes docs/command-line.md's tables from it and
// checks them in the suite. Not in --help: a tool's input, not a user's.
#include "experiments/cli/cli_common.hpp"

#include <nlohmann/json.hpp>

#include <iostream>
#include <string>

namespace ts::cli {
namespace {

nlohmann::ordered_json option_json(const CLI::Option& o) {
  nlohmann::ordered_json j;
  j["name"] = o.get_positional() ? o.get_name(true, false) : o.get_name(false, true);
  j["long"] = o.get_lnames();
  j["short"] = o.get_snames();
  j["positional"] = o.get_positional();
  j["type"] = o.get_type_name();
  j["default"] = o.get_default_str();
  j["required"] = o.get_required();
  j["flag"] = o.get_expected_max() == 0;
  j["items"] = o.get_items_expected_max();
  j["group"] = o.get_group();
  j["description"] = o.get_description();
  std::string excludes;
  for (const CLI::Option* e : o.get_excludes()) excludes += (excludes.empty() ? "" : " ") + e->get_name();
  j["excludes"] = excludes;
  std::string needs;
  for (const CLI::Option* e : o.get_needs()) needs += (needs.empty() ? "" : " ") + e->get_name();
  j["needs"] = needs;
  return j;
}

nlohmann::ordered_json app_json(const CLI::App& app, const std::string& path) {
  nlohmann::ordered_json j;
  j["command"] = path;
  j["description"] = app.get_description();
  j["options"] = nlohmann::ordered_json::array();
  for (const CLI::Option* o : app.get_options())
    if (o->get_name() != "--help" && o->get_name() != "--help-all" && !o->get_group().empty())
      j["options"].push_back(option_json(*o));
  j["subcommands"] = nlohmann::ordered_json::array();
  for (const CLI::App* sub : app.get_subcommands({}))
    j["subcommands"].push_back(app_json(*sub, path + " " + sub->get_name()));
  return j;
}

}  // namespace

void print_reference(const CLI::App& app) { std::cout << app_json(app, "touchstone").dump(1) << "\n"; }

}  // namespace ts::cli
