#include "io/result_store.hpp"

#include "io/pose_row.hpp"

#include "io/atomic_file.hpp"
#include "io/h5.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>

namespace ts::io {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

void push_pose(std::vector<double>& t, std::vector<double>& q, const Pose& T) {
  const auto row = canonical_pose_row(T);
  t.insert(t.end(), row.begin(), row.begin() + 3);
  q.insert(q.end(), row.begin() + 3, row.end());
}

/// The optional /answer_sets group: present exactly when the header has a level, every step then
/// with an answer set over every object.
void write_answer_sets(h5::Group& root, const ResultHeader& h, const std::vector<ResultStep>& steps,
                       const std::string& file) {
  const bool any = std::any_of(steps.begin(), steps.end(), [](const ResultStep& s) { return s.answer_set.has_value(); });
  if (!h.answer_set_alpha) {
    if (any) throw Error("steps carry answer sets but the header no level", file, "/answer_sets/alpha");
    return;
  }
  const double alpha = *h.answer_set_alpha;
  if (!(alpha > 0.0 && alpha < 1.0)) throw Error("alpha must lie in (0, 1)", file, "/answer_sets/alpha");
  const std::size_t K = steps.size(), n_obj = h.objects.size();
  std::vector<std::uint8_t> informative, in_set;
  std::vector<std::uint64_t> size;
  std::vector<std::int32_t> calibrated;
  std::vector<double> p, gap;
  for (const ResultStep& s : steps) {
    if (!s.answer_set) throw Error("step " + std::to_string(s.step) + " has no answer set", file, "/answer_sets");
    const ResultAnswerSet& a = *s.answer_set;
    if (a.p_value.size() != n_obj || a.log_weight_gap.size() != n_obj || a.in_set.size() != n_obj)
      throw Error("step " + std::to_string(s.step) + "'s answer set does not cover the " + std::to_string(n_obj) +
                  " objects", file, "/answer_sets");
    informative.push_back(a.informative ? 1 : 0);
    size.push_back(a.size);
    calibrated.push_back(a.calibrated_step);
    p.insert(p.end(), a.p_value.begin(), a.p_value.end());
    gap.insert(gap.end(), a.log_weight_gap.begin(), a.log_weight_gap.end());
    in_set.insert(in_set.end(), a.in_set.begin(), a.in_set.end());
  }
  auto g = root.create_group("answer_sets");
  g.set_attribute("alpha", alpha);
  g.set_attribute("calibration", h.calibration);
  g.write("informative", informative);
  g.write("size", size);
  g.write("calibrated_step", calibrated);
  g.write("p_value", p.data(), {K, n_obj});
  g.write("log_weight_gap", gap.data(), {K, n_obj});
  g.write("in_set", in_set.data(), {K, n_obj});
}

/// Reads and checks /answer_sets into the header and the steps (already read).
void read_answer_sets(const h5::Group& root, ResultData& d, const std::string& file) {
  if (!root.has_group("answer_sets")) return;
  const auto g = root.open_group("answer_sets");
  const double alpha = g.double_attribute("alpha");
  if (!(alpha > 0.0 && alpha < 1.0)) throw Error("alpha must lie in (0, 1)", file, "/answer_sets/alpha");
  d.header.answer_set_alpha = alpha;
  d.header.calibration = g.string_attribute("calibration");
  const auto K = static_cast<std::int64_t>(d.steps.size());
  const auto n_obj = static_cast<std::int64_t>(d.header.objects.size());
  const auto informative = g.read<std::uint8_t>("informative", {K});
  const auto size = g.read<std::uint64_t>("size", {K});
  const auto calibrated = g.read<std::int32_t>("calibrated_step", {K});
  const auto p = g.read<double>("p_value", {K, n_obj});
  const auto gap = g.read<double>("log_weight_gap", {K, n_obj});
  const auto in_set = g.read<std::uint8_t>("in_set", {K, n_obj});
  for (std::int64_t k = 0; k < K; ++k) {
    ResultAnswerSet a;
    if (informative[k] > 1) throw Error("informative must be 0 or 1", file, "/answer_sets/informative");
    a.informative = informative[k] == 1;
    if (size[k] > static_cast<std::uint64_t>(n_obj) || (n_obj > 0 && size[k] == 0))
      throw Error("a set of " + std::to_string(size[k]) + " classes among " + std::to_string(n_obj) + " objects", file,
                  "/answer_sets/size");
    a.size = size[k];
    if (calibrated[k] < 1) throw Error("calibrated steps start at 1", file, "/answer_sets/calibrated_step");
    a.calibrated_step = calibrated[k];
    std::size_t members = 0;
    for (std::int64_t i = k * n_obj; i < (k + 1) * n_obj; ++i) {
      if (!(p[i] > 0.0 && p[i] <= 1.0)) throw Error("p-values must lie in (0, 1]", file, "/answer_sets/p_value");
      if (!(gap[i] >= 0.0)) throw Error("gaps must be >= 0 (or +inf)", file, "/answer_sets/log_weight_gap");
      if (in_set[i] > 1 || (!a.informative && in_set[i] != 1))
        throw Error("membership must be 0 or 1, and 1 for every object of an uninformative set", file,
                    "/answer_sets/in_set");
      members += in_set[i];
      a.p_value.push_back(p[i]);
      a.log_weight_gap.push_back(gap[i]);
      a.in_set.push_back(in_set[i]);
    }
    if (members < a.size) throw Error("fewer objects in the set than its classes", file, "/answer_sets/in_set");
    d.steps[static_cast<std::size_t>(k)].answer_set = std::move(a);
  }
}

}  // namespace

ResultStep to_result_step(const StepResult& r, std::optional<std::size_t> truth_object,
                          const std::optional<Pose>& truth_pose, const SymmetryGroup* sym) {
  ResultStep s;
  s.step = r.step;
  s.valid = r.valid;
  s.contacts = r.contacts;
  s.free_points = r.free_points;
  s.candidates = r.candidates;
  s.unobservable_dof = r.unobservable_dof;
  s.posterior = r.posteriors;
  s.hypotheses = r.hypotheses;
  if (r.valid) {
    s.best_object = static_cast<int>(r.best.object);
    s.best_weight = r.best.weight;
    s.best_log_weight = r.best.log_weight;
    s.best_posterior = r.posterior;
    s.best_pose = r.best.pose;
  }
  if (truth_object) s.correct = r.valid && r.best.object == *truth_object;
  if (truth_pose && r.valid) {
    // Symmetries belong to the true object: only meaningful when the object is right.
    const bool right = truth_object && r.best.object == *truth_object;
    s.error = pose_error(r.best.pose, *truth_pose, right ? sym : nullptr);
  }
  return s;
}

void write_result(const std::filesystem::path& path, const ResultHeader& h,
                  const std::vector<ResultStep>& steps) {
  AtomicOutput out(path);
  {
    auto f = h5::File::create(out);
    auto root = f.root();
    root.set_attribute("format", kResultFormat);
    root.set_attribute("schema_version", kResultSchemaVersion);
    root.set_attribute("method", h.method);
    root.set_attribute("seed", std::to_string(h.seed));
    root.set_attribute("database", h.database);
    root.set_attribute("input", h.input);
    root.set_attribute("input_kind", h.input_kind);
    root.set_attribute("truth_object", h.truth_object);
    root.set_attribute("steps", static_cast<std::int64_t>(steps.size()));
    root.write_strings("objects", h.objects);
    auto params = root.create_group("params");
    for (const auto& [name, value] : h.params) params.set_attribute(name, value);
    if (h.truth_pose) {
      auto gt = root.create_group("ground_truth");
      std::vector<double> t, q;
      push_pose(t, q, *h.truth_pose);
      gt.write("t", t);
      gt.write("q", q);
    }

    const std::size_t K = steps.size(), n_obj = h.objects.size();
    std::vector<std::int32_t> step, best_object, dof;
    std::vector<std::uint8_t> valid, correct;
    std::vector<std::uint64_t> contacts, free_points, candidates, hyp_begin, hyp_count;
    std::vector<double> best_weight, best_log_weight, best_post, best_t, best_q, posterior;
    std::vector<double> e_pos, e_ori, e_sym_ori, e_sym_pos;
    std::vector<std::int32_t> hs, ho, hb, hi;
    std::vector<std::uint32_t> hslot;
    std::vector<std::uint8_t> hconv;
    std::vector<double> ht, hq, hlw, hw;
    for (const ResultStep& s : steps) {
      step.push_back(s.step);
      valid.push_back(s.valid ? 1 : 0);
      correct.push_back(s.correct ? (*s.correct ? 1 : 0) : 2);
      contacts.push_back(s.contacts);
      free_points.push_back(s.free_points);
      candidates.push_back(s.candidates);
      dof.push_back(s.unobservable_dof);
      best_object.push_back(s.best_object);
      best_weight.push_back(s.best_weight);
      best_log_weight.push_back(s.best_log_weight);
      best_post.push_back(s.best_posterior);
      push_pose(best_t, best_q, s.best_pose);
      if (s.posterior.size() != n_obj)
        throw Error("posterior has " + std::to_string(s.posterior.size()) + " objects, expected " +
                        std::to_string(n_obj), path.string(), "/steps/posterior");
      posterior.insert(posterior.end(), s.posterior.begin(), s.posterior.end());
      e_pos.push_back(s.error ? s.error->position_m : kNaN);
      e_ori.push_back(s.error ? s.error->orientation_deg : kNaN);
      e_sym_ori.push_back(s.error ? s.error->symmetric_orientation_deg : kNaN);
      e_sym_pos.push_back(s.error ? s.error->symmetric_position_m : kNaN);
      hyp_begin.push_back(hs.size());
      hyp_count.push_back(s.hypotheses.size());
      for (const Hypothesis& x : s.hypotheses) {
        hs.push_back(s.step);
        ho.push_back(static_cast<std::int32_t>(x.object));
        push_pose(ht, hq, x.pose);
        hlw.push_back(x.log_weight);
        hw.push_back(x.weight);
        hb.push_back(x.born);
        hslot.push_back(x.slot);
        hi.push_back(x.icp_iterations);
        hconv.push_back(x.icp_converged ? 1 : 0);
      }
    }
    auto st = root.create_group("steps");
    st.write("step", step);
    st.write("valid", valid);
    st.write("correct", correct);
    st.write("contacts", contacts);
    st.write("free_points", free_points);
    st.write("candidates", candidates);
    st.write("unobservable_dof", dof);
    st.write("best_object", best_object);
    st.write("best_weight", best_weight);
    st.write("best_log_weight", best_log_weight);
    st.write("best_posterior", best_post);
    st.write("best_t", best_t.data(), {K, 3});
    st.write("best_q", best_q.data(), {K, 4});
    st.write("posterior", posterior.data(), {K, n_obj});
    st.write("position_error_m", e_pos);
    st.write("orientation_error_deg", e_ori);
    st.write("symmetric_orientation_error_deg", e_sym_ori);
    st.write("symmetric_position_error_m", e_sym_pos);
    st.write("hypotheses_begin", hyp_begin);
    st.write("hypotheses_count", hyp_count);
    const std::uint64_t H = hs.size();
    auto hy = root.create_group("hypotheses");
    hy.write("step", hs);
    hy.write("object", ho);
    hy.write("t", ht.data(), {H, 3});
    hy.write("q", hq.data(), {H, 4});
    hy.write("log_weight", hlw);
    hy.write("weight", hw);
    hy.write("born", hb);
    hy.write("slot", hslot);
    hy.write("icp_iterations", hi);
    hy.write("icp_converged", hconv);
    write_answer_sets(root, h, steps, path.string());
    f.close();
  }
  out.commit();
}

ResultData read_result(const std::filesystem::path& path) {
  ResultData d;
  auto f = h5::File::open(path);
  auto root = f.root();
  const std::string file = path.string();
  if (!root.has_attribute("format") || root.string_attribute("format") != kResultFormat)
    throw Error("not a Touchstone result file", file, "/format");
  if (root.int_attribute("schema_version") != kResultSchemaVersion)
    throw Error("unsupported result schema version " +
                    std::to_string(root.int_attribute("schema_version")),
                file, "/schema_version");
  ResultHeader& h = d.header;
  h.method = root.string_attribute("method");
  {
    const std::string seed = root.string_attribute("seed");   // a string: uint64 does not fit HDF5's int attributes
    const auto [end, ec] = std::from_chars(seed.data(), seed.data() + seed.size(), h.seed);
    if (seed.empty() || ec != std::errc{} || end != seed.data() + seed.size())
      throw Error("'" + seed.substr(0, 40) + "' is not a seed (a whole number below 2^64)", file, "/seed");
  }
  h.database = root.string_attribute("database");
  h.input = root.string_attribute("input");
  h.input_kind = root.string_attribute("input_kind");
  h.truth_object = root.string_attribute("truth_object");
  h.objects = root.read_strings("objects");
  const auto params = root.open_group("params");
  for (const std::string& a : params.attributes()) h.params.emplace_back(a, params.double_attribute(a));
  if (root.has_group("ground_truth")) {
    const auto gt = root.open_group("ground_truth");
    const auto t = gt.read<double>("t", {3});
    const auto q = gt.read<double>("q", {4});
    h.truth_pose = pose_from_row(t.data(), q.data());
  }
  const std::int64_t K64 = root.int_attribute("steps");
  const auto K = static_cast<std::int64_t>(K64);
  const auto n_obj = static_cast<std::int64_t>(h.objects.size());
  const auto st = root.open_group("steps");
  const auto step = st.read<std::int32_t>("step", {K});
  const auto valid = st.read<std::uint8_t>("valid", {K});
  const auto correct = st.read<std::uint8_t>("correct", {K});
  const auto contacts = st.read<std::uint64_t>("contacts", {K});
  const auto free_points = st.read<std::uint64_t>("free_points", {K});
  const auto candidates = st.read<std::uint64_t>("candidates", {K});
  const auto dof = st.read<std::int32_t>("unobservable_dof", {K});
  const auto best_object = st.read<std::int32_t>("best_object", {K});
  const auto bw = st.read<double>("best_weight", {K});
  const auto blw = st.read<double>("best_log_weight", {K});
  const auto bp = st.read<double>("best_posterior", {K});
  const auto bt = st.read<double>("best_t", {K, 3});
  const auto bq = st.read<double>("best_q", {K, 4});
  const auto post = st.read<double>("posterior", {K, n_obj});
  const auto e_pos = st.read<double>("position_error_m", {K});
  const auto e_ori = st.read<double>("orientation_error_deg", {K});
  const auto e_sori = st.read<double>("symmetric_orientation_error_deg", {K});
  const auto e_spos = st.read<double>("symmetric_position_error_m", {K});
  const auto hb = st.read<std::uint64_t>("hypotheses_begin", {K});
  const auto hc = st.read<std::uint64_t>("hypotheses_count", {K});
  const auto hy = root.open_group("hypotheses");
  h5::Shape hs_shape;
  const auto hobj = hy.read<std::int32_t>("object", {h5::kAny}, &hs_shape);
  const auto H = static_cast<std::int64_t>(hs_shape[0]);
  const auto ht = hy.read<double>("t", {H, 3});
  const auto hq = hy.read<double>("q", {H, 4});
  const auto hlw = hy.read<double>("log_weight", {H});
  const auto hw = hy.read<double>("weight", {H});
  const auto hborn = hy.read<std::int32_t>("born", {H});
  const auto hslot = hy.read<std::uint32_t>("slot", {H});
  const auto hit = hy.read<std::int32_t>("icp_iterations", {H});
  const auto hconv = hy.read<std::uint8_t>("icp_converged", {H});
  for (std::int64_t k = 0; k < K; ++k) {
    ResultStep s;
    s.step = step[k];
    s.valid = valid[k] != 0;
    if (correct[k] != 2) s.correct = correct[k] == 1;
    s.contacts = contacts[k];
    s.free_points = free_points[k];
    s.candidates = candidates[k];
    s.unobservable_dof = dof[k];
    s.best_object = best_object[k];
    s.best_weight = bw[k];
    s.best_log_weight = blw[k];
    s.best_posterior = bp[k];
    s.best_pose = pose_from_row(&bt[3 * k], &bq[4 * k]);
    s.posterior.assign(post.begin() + k * n_obj, post.begin() + (k + 1) * n_obj);
    if (!std::isnan(e_pos[k]))
      s.error = PoseError{e_pos[k], e_ori[k], e_sori[k], e_spos[k]};
    if (hb[k] + hc[k] > static_cast<std::uint64_t>(H))
      throw Error("hypothesis range out of bounds", file, "/steps/hypotheses_begin");
    for (std::uint64_t j = hb[k]; j < hb[k] + hc[k]; ++j) {
      Hypothesis x;
      x.object = static_cast<std::uint32_t>(hobj[j]);
      x.pose = pose_from_row(&ht[3 * j], &hq[4 * j]);
      x.log_weight = hlw[j];
      x.weight = hw[j];
      x.born = hborn[j];
      x.slot = hslot[j];
      x.icp_iterations = hit[j];
      x.icp_converged = hconv[j] != 0;
      s.hypotheses.push_back(x);
    }
    d.steps.push_back(std::move(s));
  }
  read_answer_sets(root, d, file);
  return d;
}

}  // namespace ts::io
