#include "experiments/calibration.hpp"

#include "io/atomic_file.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

namespace ts::experiments {

namespace {
constexpr const char* kFormat = "touchstone-calibration";
constexpr double kAgreementRadius = 0.01;  ///< m: hypotheses within this of the best agree
}  // namespace

const std::vector<std::string>& confidence_feature_names() {
  static const std::vector<std::string> names{
      "posterior_best",     // posterior of the named object (weights summed by object)
      "posterior_margin",   // minus the largest posterior of another object
      "log_residual",       // ln(-ln wt) of the best hypothesis: its Eq. 4-9 misfit
      "agreement",          // share of hypotheses on the named object within 1 cm of its pose
      "log_contacts"};      // ln(1 + contacts)
  return names;
}

std::vector<double> confidence_features(const StepResult& r) {
  double best = 0.0, other = 0.0, misfit = 1.0, agreement = 0.0;
  if (r.valid) {
    best = r.posterior;
    for (std::size_t i = 0; i < r.posteriors.size(); ++i)
      if (i != r.best.object) other = std::max(other, r.posteriors[i]);
    if (std::isfinite(r.best.log_weight)) misfit = std::clamp(-r.best.log_weight, 1e-12, 1e3);
    std::size_t agree = 0;
    for (const Hypothesis& h : r.hypotheses)
      if (h.object == r.best.object &&
          (h.pose.translation() - r.best.pose.translation()).norm() < kAgreementRadius)
        ++agree;
    if (!r.hypotheses.empty()) agreement = static_cast<double>(agree) / static_cast<double>(r.hypotheses.size());
  }
  return {best, best - other, std::log(misfit), agreement, std::log1p(static_cast<double>(r.contacts))};
}

double LogisticModel::predict(std::span<const double> f) const {
  if (f.size() + 1 != coef.size() || mean.size() != f.size() || scale.size() != f.size())
    throw Error("the confidence model expects " + std::to_string(mean.size()) + " features, got " +
                std::to_string(f.size()), {}, "features");
  double z = coef[0];
  for (std::size_t i = 0; i < f.size(); ++i) z += coef[i + 1] * (f[i] - mean[i]) / scale[i];
  // Stable in both tails.
  return z >= 0 ? 1.0 / (1.0 + std::exp(-z)) : std::exp(z) / (1.0 + std::exp(z));
}

LogisticModel fit_logistic(const std::vector<std::vector<double>>& rows, const std::vector<int>& labels,
                           double l2) {
  if (rows.empty() || rows.size() != labels.size())
    throw Error("a logistic fit needs as many labels as rows, and at least one", {}, "calibration");
  const std::size_t n = rows.size(), f = rows.front().size();
  LogisticModel m;
  m.mean.assign(f, 0.0);
  m.scale.assign(f, 0.0);
  for (const auto& r : rows) {
    if (r.size() != f) throw Error("rows of a logistic fit differ in length", {}, "calibration");
    for (std::size_t j = 0; j < f; ++j) {
      if (!std::isfinite(r[j])) throw Error("a non-finite feature in a logistic fit", {}, "calibration");
      m.mean[j] += r[j];
    }
  }
  for (double& v : m.mean) v /= static_cast<double>(n);
  for (const auto& r : rows)
    for (std::size_t j = 0; j < f; ++j) m.scale[j] += (r[j] - m.mean[j]) * (r[j] - m.mean[j]);
  for (double& v : m.scale) v = std::max(std::sqrt(v / static_cast<double>(n)), 1e-9);
  Eigen::MatrixXd x(n, f + 1);
  Eigen::VectorXd y(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (labels[i] != 0 && labels[i] != 1) throw Error("labels of a logistic fit must be 0 or 1", {}, "calibration");
    x(static_cast<Eigen::Index>(i), 0) = 1.0;
    for (std::size_t j = 0; j < f; ++j)
      x(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j + 1)) = (rows[i][j] - m.mean[j]) / m.scale[j];
    y(static_cast<Eigen::Index>(i)) = labels[i];
  }
  const auto k = static_cast<Eigen::Index>(f + 1);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(k);
  Eigen::MatrixXd penalty = Eigen::MatrixXd::Identity(k, k) * l2 * static_cast<double>(n);
  penalty(0, 0) = 1e-9;  // the bias is not shrunk (a tiny ridge keeps all-0/all-1 labels finite)
  for (int it = 0; it < 100; ++it) {
    const Eigen::VectorXd z = x * w;
    Eigen::VectorXd p(z.size()), s(z.size());
    for (Eigen::Index i = 0; i < z.size(); ++i) {
      p(i) = z(i) >= 0 ? 1.0 / (1.0 + std::exp(-z(i))) : std::exp(z(i)) / (1.0 + std::exp(z(i)));
      s(i) = std::max(p(i) * (1.0 - p(i)), 1e-12);
    }
    const Eigen::VectorXd g = x.transpose() * (y - p) - penalty * w;
    const Eigen::MatrixXd h = x.transpose() * s.asDiagonal() * x + penalty;
    const Eigen::VectorXd step = h.ldlt().solve(g);
    w += step;
    if (step.lpNorm<Eigen::Infinity>() < 1e-10) break;
  }
  // Labels all alike leave the bias to the tiny ridge: keep it within a sane range.
  w(0) = std::clamp(w(0), -30.0, 30.0);
  m.coef.assign(w.data(), w.data() + w.size());
  return m;
}

double choose_open_set_threshold(std::vector<double> right, std::size_t runs, double max_drop) {
  if (!(max_drop >= 0.0 && max_drop < 1.0))
    throw Error("the open-set drop must lie in [0, 1)", {}, "--open-set-drop");
  const auto k = static_cast<std::size_t>(std::floor(max_drop * static_cast<double>(runs) + 1e-9));
  if (k >= right.size()) return 1.0;
  std::sort(right.begin(), right.end());
  return right[k];
}

namespace {

nlohmann::ordered_json model_json(const LogisticModel& m) {
  nlohmann::ordered_json j;
  j["mean"] = m.mean;
  j["scale"] = m.scale;
  j["coef"] = m.coef;
  return j;
}

LogisticModel model_from(const nlohmann::ordered_json& j, const std::string& key, std::size_t features,
                         const std::string& file) {
  if (!j.contains(key) || !j[key].is_object()) throw Error("missing the model object", file, key);
  const auto& m = j[key];
  LogisticModel out;
  auto numbers = [&](const char* name, std::size_t size) {
    const std::string where = key + "." + name;
    if (!m.contains(name) || !m[name].is_array() || m[name].size() != size)
      throw Error("expected an array of " + std::to_string(size) + " numbers", file, where);
    std::vector<double> v;
    for (const auto& x : m[name]) {
      if (!x.is_number() || !std::isfinite(x.get<double>())) throw Error("expected finite numbers", file, where);
      v.push_back(x.get<double>());
    }
    return v;
  };
  out.mean = numbers("mean", features);
  out.scale = numbers("scale", features);
  out.coef = numbers("coef", features + 1);
  for (double s : out.scale)
    if (!(s > 0.0)) throw Error("scales must be positive", file, key + ".scale");
  return out;
}

}  // namespace

nlohmann::ordered_json to_json(const Calibration& c) {
  nlohmann::ordered_json j;
  j["format"] = kFormat;
  j["version"] = Calibration::kVersion;
  j["database_fingerprint"] = c.database_fingerprint;
  j["features"] = c.features;
  j["object"] = model_json(c.object);
  j["pose"] = model_json(c.pose);
  j["open_set_threshold"] = c.open_set_threshold ? nlohmann::ordered_json(*c.open_set_threshold) : nullptr;
  j["provenance"] = c.provenance.is_null() ? nlohmann::ordered_json::object() : c.provenance;
  return j;
}

void write_calibration(const std::filesystem::path& file, const Calibration& c) {
  io::AtomicOutput out(file);
  {
    std::ofstream f(out.temp_path());
    f << to_json(c).dump(1) << "\n";
    f.close();
    if (!f) throw Error("cannot write the calibration file", file.string());
  }
  out.commit();
}

Calibration read_calibration(const std::filesystem::path& path, const std::string& database_fingerprint) {
  const std::string file = path.string();
  std::ifstream in(path);
  if (!in) throw Error("cannot read the calibration file", file);
  std::ostringstream text;
  text << in.rdbuf();
  const auto j = nlohmann::ordered_json::parse(text.str(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw Error("the calibration file is not a JSON object", file);
  if (!j.contains("format") || j["format"] != kFormat)
    throw Error("not a Touchstone calibration file (format must be \"" + std::string(kFormat) + "\")", file, "format");
  if (!j.contains("version") || !j["version"].is_number_integer() || j["version"].get<long long>() != Calibration::kVersion)
    throw Error("calibration version " + (j.contains("version") ? j["version"].dump() : std::string("absent")) +
                " is not supported (this build reads version " + std::to_string(Calibration::kVersion) + ")",
                file, "version");
  Calibration c;
  if (!j.contains("database_fingerprint") || !j["database_fingerprint"].is_string())
    throw Error("missing the database fingerprint", file, "database_fingerprint");
  c.database_fingerprint = j["database_fingerprint"].get<std::string>();
  if (!database_fingerprint.empty() && c.database_fingerprint != database_fingerprint)
    throw Error("the calibration was fitted for another database (fingerprint " +
                c.database_fingerprint.substr(0, 12) + "..., this one " + database_fingerprint.substr(0, 12) +
                "...): fit one on runs of this database with `touchstone calibrate`", file, "database_fingerprint");
  if (!j.contains("features") || !j["features"].is_array()) throw Error("missing the feature names", file, "features");
  for (const auto& f : j["features"]) {
    if (!f.is_string()) throw Error("feature names must be strings", file, "features");
    c.features.push_back(f.get<std::string>());
  }
  if (c.features != confidence_feature_names())
    throw Error("the calibration's features differ from this build's (" + j["features"].dump() +
                "): refit it with this version", file, "features");
  c.object = model_from(j, "object", c.features.size(), file);
  c.pose = model_from(j, "pose", c.features.size(), file);
  if (j.contains("open_set_threshold") && !j["open_set_threshold"].is_null()) {
    const auto& t = j["open_set_threshold"];
    if (!t.is_number() || !(t.get<double>() >= 0.0 && t.get<double>() <= 1.0))
      throw Error("the open-set threshold must be a number in [0, 1] or null", file, "open_set_threshold");
    c.open_set_threshold = t.get<double>();
  }
  c.provenance = j.contains("provenance") ? j["provenance"] : nlohmann::ordered_json::object();
  return c;
}

}  // namespace ts::experiments
