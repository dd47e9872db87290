// Families of parametric objects of structured underwater work (subsea pipework, intervention
// panels, fasteners): each family is a list of drawn parameters with their ranges and a CSG
// construction in metres at true size (see families.cpp for the geometry of each).
#pragma once

#include "datasets/catalogue/csg.hpp"

#include <string>
#include <vector>

namespace ts::catalogue {

/// How a parameter is drawn from [lo, hi].
enum class Draw {
  Uniform,     ///< uniform in [lo, hi]
  LogUniform,  ///< log-uniform in [lo, hi] (lo > 0)
  Integer,     ///< uniform integer in [lo, hi]
  Choice       ///< an index into `choices` (lo, hi: the allowed index range)
};

struct ParamSpec {
  std::string name;
  std::string unit;                  ///< "m", "deg", "1" (ratio), "count", "choice"
  Draw draw = Draw::Uniform;
  double lo = 0.0, hi = 0.0;
  std::vector<std::string> choices;  ///< Choice only: labels
  std::string help;
  bool positive() const { return unit == "m" || draw == Draw::LogUniform; }
};

/// Drawn values, in the order of the family's specs.
struct Params {
  std::vector<double> values;
  const std::vector<ParamSpec>* specs = nullptr;
  double operator()(const std::string& name) const;   ///< throws ts::Error on an unknown name
  /// "od=0.0603 m, wall_ratio=0.08, angle=90 (choice)".
  std::string text() const;
  /// The value as written in catalogue.tsv: a choice's label, else the number.
  std::string value_text(std::size_t i) const;
};

/// A solid plus what the voxel size must resolve.
struct Construction {
  Shape shape;
  double extent = 0.0;       ///< largest dimension estimate, m
  double min_feature = 0.0;  ///< thinnest wall or rod diameter that must be resolved, m
};

struct Family {
  std::string name;          ///< "flange_blind"
  std::string description;   ///< one line
  std::vector<ParamSpec> params;
  double weight = 1.0;       ///< relative share of the catalogue
  /// Build the solid; `voxel` (m) sets the tessellation of round primitives.
  Construction (*build)(const Params& p, double voxel) = nullptr;
};

/// Every family, in catalogue order.
const std::vector<Family>& all_families();
/// The family called `name`, or nullptr.
const Family* find_family(const std::string& name);

/// Draw a family's parameters from `rng` (the family's specs, in order).
Params draw_params(const Family& family, Rng& rng);
/// Parameters given by value (tests, reproductions): `values` in spec order.
Params make_params(const Family& family, std::vector<double> values);

}  // namespace ts::catalogue
