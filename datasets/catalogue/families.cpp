// The catalogue's families. Every construction is in metres, at true size, in the object's
// natural frame (pipe axes along x or z, mounting faces on z = 0). Dimension series follow the
// usual standards loosely: EN 1092-1 PN16 flanges, ISO 4032/4014 hex nuts and bolts.
#include "datasets/catalogue/families.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

namespace ts::catalogue {

namespace {

constexpr double kPi = std::numbers::pi;

// --- parameter helpers -----------------------------------------------------------------------
ParamSpec uni(std::string name, double lo, double hi, std::string unit, std::string help) {
  return {std::move(name), std::move(unit), Draw::Uniform, lo, hi, {}, std::move(help)};
}
ParamSpec logu(std::string name, double lo, double hi, std::string help) {
  return {std::move(name), "m", Draw::LogUniform, lo, hi, {}, std::move(help)};
}
ParamSpec integer(std::string name, double lo, double hi, std::string help) {
  return {std::move(name), "count", Draw::Integer, lo, hi, {}, std::move(help)};
}
ParamSpec choice(std::string name, std::vector<std::string> labels, std::string help) {
  const double hi = static_cast<double>(labels.size() - 1);
  return {std::move(name), "choice", Draw::Choice, 0.0, hi, std::move(labels), std::move(help)};
}

// --- geometry helpers ------------------------------------------------------------------------
/// Round rod of radius r from a to b.
Shape rod(const Vec3& a, const Vec3& b, double r, double voxel) {
  const Vec3 d = b - a;
  return Shape::leaf(prim::cylinder(r, 0.0, d.norm(), prim::segments(r, voxel))).moved(frame(a, d));
}
Shape ball(const Vec3& c, double r, double voxel) {
  Pose T = Pose::Identity();
  T.translation() = c;
  return Shape::leaf(prim::sphere(r, prim::segments(r, voxel))).moved(T);
}
Shape box(const Vec3& lo, const Vec3& hi) { return Shape::leaf(prim::box(lo, hi)); }
Shape lathe(const std::vector<Vec2>& profile, double r_max, double voxel) {
  return Shape::leaf(prim::lathe(profile, prim::segments(r_max, voxel)));
}
Shape tube(double ri, double ro, double z0, double z1, double voxel) {
  return Shape::leaf(prim::tube(ri, ro, z0, z1, prim::segments(ro, voxel)));
}
Pose translation(const Vec3& t) {
  Pose T = Pose::Identity();
  T.translation() = t;
  return T;
}

// --- series ----------------------------------------------------------------------------------
struct FlangeSize {
  const char* dn;
  double pipe_od, D, K, hole;  // m: pipe OD, flange OD, bolt circle, bolt hole
  int bolts;
};
// EN 1092-1 PN16 (rounded).
const FlangeSize kFlanges[] = {
    {"DN15", 0.0213, 0.095, 0.065, 0.014, 4},  {"DN20", 0.0269, 0.105, 0.075, 0.014, 4},
    {"DN25", 0.0337, 0.115, 0.085, 0.014, 4},  {"DN32", 0.0424, 0.140, 0.100, 0.018, 4},
    {"DN40", 0.0483, 0.150, 0.110, 0.018, 4},  {"DN50", 0.0603, 0.165, 0.125, 0.018, 4},
    {"DN65", 0.0761, 0.185, 0.145, 0.018, 8},  {"DN80", 0.0889, 0.200, 0.160, 0.018, 8},
    {"DN100", 0.1143, 0.220, 0.180, 0.018, 8}, {"DN125", 0.1397, 0.250, 0.210, 0.018, 8},
    {"DN150", 0.1683, 0.285, 0.240, 0.022, 8}, {"DN200", 0.2191, 0.340, 0.295, 0.022, 12},
    {"DN250", 0.2730, 0.405, 0.355, 0.026, 12}, {"DN300", 0.3239, 0.460, 0.410, 0.026, 12}};

std::vector<std::string> flange_labels() {
  std::vector<std::string> l;
  for (const auto& f : kFlanges) l.push_back(f.dn);
  return l;
}

struct MetricSize {
  const char* m;
  double d, s, k;  // m: thread diameter, across flats, bolt head height
};
const MetricSize kMetric[] = {{"M10", 0.010, 0.016, 0.0064}, {"M12", 0.012, 0.018, 0.0075},
                              {"M16", 0.016, 0.024, 0.010},  {"M20", 0.020, 0.030, 0.0125},
                              {"M24", 0.024, 0.036, 0.015},  {"M30", 0.030, 0.046, 0.0187},
                              {"M36", 0.036, 0.055, 0.0225}, {"M42", 0.042, 0.065, 0.026},
                              {"M48", 0.048, 0.075, 0.030},  {"M56", 0.056, 0.085, 0.035},
                              {"M64", 0.064, 0.095, 0.040}};

std::vector<std::string> metric_labels(int first, int last) {
  std::vector<std::string> l;
  for (int i = first; i <= last; ++i) l.push_back(kMetric[i].m);
  return l;
}

/// Bolt holes: n rods along z at radius rc, from z0 to z1.
Shape bolt_circle(int n, double rc, double r, double z0, double z1, double voxel, double phase) {
  std::vector<Shape> holes;
  for (int i = 0; i < n; ++i) {
    const double a = phase + 2.0 * kPi * i / n;
    const Vec3 c(rc * std::cos(a), rc * std::sin(a), 0.0);
    holes.push_back(rod(c + Vec3(0, 0, z0), c + Vec3(0, 0, z1), r, voxel));
  }
  return unite(holes);
}

// --- pipework --------------------------------------------------------------------------------
Construction elbow(const Params& p, double v) {
  const double od = p("od"), ro = od / 2, t = p("wall_ratio") * od, ri = ro - t;
  const double R = p("bend_ratio") * od, L = p("tangent_ratio") * od;
  const double angle = p("angle") == 0 ? kPi / 4 : kPi / 2;
  const int seg_major = prim::segments(R + ro, v), seg_minor = prim::segments(ro, v);
  const Shape wedge = Shape::leaf(prim::sector(R + 2 * ro, angle, -2 * ro, 2 * ro));
  const Vec3 p0(R, 0, 0), d0(0, -1, 0);
  const Vec3 p1(R * std::cos(angle), R * std::sin(angle), 0), d1(-std::sin(angle), std::cos(angle), 0);
  const double m = 2 * v;  // the bore leaves the end faces
  Shape outer = Shape::leaf(prim::torus(R, ro, seg_major, seg_minor)) & wedge;
  Shape bore = Shape::leaf(prim::torus(R, ri, seg_major, seg_minor)) & wedge;
  if (L > 0) outer = outer | rod(p0, p0 + L * d0, ro, v) | rod(p1, p1 + L * d1, ro, v);
  bore = bore | rod(p0 - 0.5 * m * d0, p0 + (L + m) * d0, ri, v) | rod(p1 - 0.5 * m * d1, p1 + (L + m) * d1, ri, v);
  return {outer - bore, R + ro + L, t};
}

Construction tee(const Params& p, double v) {
  const double od = p("od"), ro = od / 2, t = p("wall_ratio") * od, ri = ro - t;
  const double rb = p("branch_ratio") * ro, rbi = rb - t;
  const double Lr = p("run_ratio") * od, H = p("height_ratio") * od, m = 2 * v;
  const Shape outer = rod({-Lr / 2, 0, 0}, {Lr / 2, 0, 0}, ro, v) | rod({0, 0, 0}, {0, 0, H}, rb, v);
  const Shape bore = rod({-Lr / 2 - m, 0, 0}, {Lr / 2 + m, 0, 0}, ri, v) | rod({0, 0, 0}, {0, 0, H + m}, rbi, v);
  return {outer - bore, std::max(Lr, H + ro), t};
}

Construction reducer(const Params& p, double v) {
  const double od = p("od"), ro1 = od / 2, ro2 = p("ratio") * ro1, t = p("wall_ratio") * od;
  const double L = p("length_ratio") * od, c = p("cone_fraction") * L;
  const double a = (L - c) / 2, b = a + c;
  return {lathe({{ro1 - t, 0}, {ro1, 0}, {ro1, a}, {ro2, b}, {ro2, L}, {ro2 - t, L}, {ro2 - t, b}, {ro1 - t, a}}, ro1, v),
          std::max(L, od), t};
}

Construction end_cap(const Params& p, double v) {
  const double od = p("od"), ro = od / 2, t = p("wall_ratio") * od, ri = ro - t;
  const double s = p("skirt_ratio") * od, ho = p("head_ratio") * od, hi = ho - t;
  std::vector<Vec2> prof{{ri, 0}, {ro, 0}, {ro, s}};
  const int n = std::max(8, prim::segments(ro, v) / 4);
  for (int k = 1; k <= n; ++k) {
    const double a = kPi / 2 * k / n;
    prof.emplace_back(k == n ? 0.0 : ro * std::cos(a), s + ho * std::sin(a));
  }
  for (int k = n; k >= 1; --k) {
    const double a = kPi / 2 * k / n;
    prof.emplace_back(k == n ? 0.0 : ri * std::cos(a), s + hi * std::sin(a));
  }
  prof.emplace_back(ri, s);
  return {lathe(prof, ro, v), std::max(od, s + ho), t};
}

/// Raised-face radius and flange thickness of a PN16 size.
double raised_face_radius(const FlangeSize& f) {
  const double pr = f.pipe_od / 2, lim = f.K / 2 - f.hole / 2;
  return pr + 0.6 * (lim - pr);
}
double flange_thickness(const FlangeSize& f, double ratio) { return ratio * (0.012 + 0.045 * f.D); }

Construction flange_weld_neck(const Params& p, double v) {
  const auto& f = kFlanges[static_cast<int>(p("dn"))];
  const double T = flange_thickness(f, p("thickness_ratio")), h = p("raised_face"), rf = raised_face_radius(f);
  const double pr = f.pipe_od / 2, wall = std::max(0.0028, p("wall_ratio") * f.pipe_od), rb = pr - wall;
  const double Hh = p("hub_ratio") * (0.03 + 0.08 * f.D), r0 = pr + 0.45 * (rf - pr), m = 2 * v;
  const Shape body = lathe({{0, -h}, {rf, -h}, {rf, 0}, {f.D / 2, 0}, {f.D / 2, T}, {r0, T}, {pr, T + Hh}, {0, T + Hh}},
                           f.D / 2, v);
  const Shape holes = bolt_circle(f.bolts, f.K / 2, f.hole / 2, -h - m, T + m, v, kPi / f.bolts);
  const Shape bore = rod({0, 0, -h - m}, {0, 0, T + Hh + m}, rb, v);
  return {body - holes - bore, std::max(f.D, T + Hh + h), std::min(wall, T / 2)};
}

Construction flange_blind(const Params& p, double v) {
  const auto& f = kFlanges[static_cast<int>(p("dn"))];
  const double T = flange_thickness(f, p("thickness_ratio")), h = p("raised_face"), rf = raised_face_radius(f);
  const double R = p("od_ratio") * f.D / 2, m = 2 * v;  // outside diameter: the standard's, or a maker's larger one
  const Shape body = lathe({{0, -h}, {rf, -h}, {rf, 0}, {R, 0}, {R, T}, {0, T}}, R, v);
  const Shape holes = bolt_circle(f.bolts, f.K / 2, f.hole / 2, -h - m, T + m, v, kPi / f.bolts);
  return {body - holes, 2 * R, std::min(T / 2, f.hole)};
}

Construction valve(const Params& p, double v) {
  const double od = p("od"), ro = od / 2, ri = 0.8 * ro, F = p("length_ratio") * od;
  const double bd = p("body_ratio") * od, m = 2 * v;
  const bool ball_body = p("kind") == 0, wheel = p("actuator") == 0;
  // Ends: pipe run with an end flange at each face.
  const double ft = 0.12 * od, fr = 0.95 * od;
  std::vector<Shape> parts{rod({-F / 2, 0, 0}, {F / 2, 0, 0}, ro, v), rod({-F / 2, 0, 0}, {-F / 2 + ft, 0, 0}, fr, v),
                           rod({F / 2 - ft, 0, 0}, {F / 2, 0, 0}, fr, v)};
  double top = 0;
  if (ball_body) {
    parts.push_back(ball({0, 0, 0}, bd / 2, v));
    parts.push_back(rod({0, 0, 0}, {0, 0, 0.62 * bd}, 0.3 * bd, v));  // stem housing
    top = 0.62 * bd;
  } else {
    parts.push_back(box({-0.4 * bd, -0.3 * bd, -0.45 * bd}, {0.4 * bd, 0.3 * bd, 0.45 * bd}));
    parts.push_back(rod({0, 0, 0.45 * bd}, {0, 0, 0.45 * bd + 0.15 * od}, 0.42 * bd, v));  // bonnet flange
    parts.push_back(rod({0, 0, 0.45 * bd}, {0, 0, 1.1 * bd}, 0.22 * bd, v));               // bonnet
    top = 1.1 * bd;
  }
  const double rs = std::max(0.004, 0.1 * od), H = top + p("stem_ratio") * od;
  parts.push_back(rod({0, 0, top - m}, {0, 0, H + 2 * rs}, rs, v));
  const double span = p("actuator_ratio") * F;
  double extent = std::max(F, H);
  if (wheel) {
    const double Rw = span / 2, rw = std::max(0.05 * Rw, 0.6 * rs);
    parts.push_back(Shape::leaf(prim::torus(Rw, rw, prim::segments(Rw, v), prim::segments(rw, v))).moved(translation({0, 0, H})));
    parts.push_back(rod({0, 0, H - 1.5 * rs}, {0, 0, H + 1.5 * rs}, 2 * rs, v));
    for (int k = 0; k < 4; ++k) {
      const double a = kPi / 4 + kPi / 2 * k;
      parts.push_back(rod({0, 0, H}, {Rw * std::cos(a), Rw * std::sin(a), H}, 0.8 * rw, v));
    }
    extent = std::max(extent, 2 * Rw);
  } else {
    const double w = std::max(2.2 * rs, 0.25 * od), t = std::max(1.2 * rs, 0.08 * od);
    parts.push_back(rod({0, 0, H - 1.5 * rs}, {0, 0, H + 1.5 * rs}, 2 * rs, v));
    parts.push_back(box({-1.5 * rs, -w / 2, H - t / 2}, {span, w / 2, H + t / 2}));
    parts.push_back(ball({span, 0, H}, 0.6 * w, v));  // lever grip
    extent = std::max(extent, span + F / 2);
  }
  const Shape bore = rod({-F / 2 - m, 0, 0}, {F / 2 + m, 0, 0}, ri, v);
  return {unite(parts) - bore, extent, std::min(2 * rs, ro - ri)};
}

// --- intervention tooling --------------------------------------------------------------------
Construction t_handle(const Params& p, double v) {
  const double d = p("shaft_d"), rs = d / 2, Ls = p("shaft_ratio") * d, Lb = p("bar_ratio") * d;
  const double rb = p("bar_d_ratio") * rs, rc = p("collar_ratio") * rs, tc = 0.35 * d;
  std::vector<Shape> parts{
      lathe({{0, 0}, {0.7 * rs, 0}, {rs, 0.3 * rs}, {rs, Ls}, {0, Ls}}, rs, v),  // shaft, chamfered tip
      rod({-Lb / 2, 0, Ls}, {Lb / 2, 0, Ls}, rb, v), ball({-Lb / 2, 0, Ls}, rb, v), ball({Lb / 2, 0, Ls}, rb, v),
      rod({0, 0, 0.3 * Ls}, {0, 0, 0.3 * Ls + tc}, rc, v), ball({0, 0, Ls}, 1.3 * rs, v)};
  return {unite(parts), std::max(Ls + rb, Lb + 2 * rb), std::min(d, 2 * rb)};
}

Construction hot_stab(const Params& p, double v) {
  const double d = p("body_d"), ro = d / 2, L = p("length_ratio") * d, rb = p("bore_ratio") * ro;
  const double Rf = p("funnel_ratio") * ro, Lf = 0.6 * (Rf - ro) + 0.2 * d, tf = 0.12 * d, depth = 0.85 * L;
  const Shape body = lathe({{0, 0}, {ro, 0}, {ro, L}, {Rf, L + Lf}, {Rf - tf, L + Lf}, {rb, L}, {rb, L - depth}, {0, L - depth}}, Rf, v);
  const double S = p("plate_ratio") * d, tp = 0.12 * d, zp = 0.2 * L, m = 2 * v;
  const Shape plate = box({-S / 2, -S / 2, zp}, {S / 2, S / 2, zp + tp});
  std::vector<Shape> holes;
  const double hc = 0.5 * (S / 2 + ro) * 1.0, hr = std::min(0.06 * d, 0.25 * (S / 2 - ro));
  for (int k = 0; k < 4; ++k) {
    const double a = kPi / 4 + kPi / 2 * k;
    const Vec3 c(hc * std::cos(a) * 1.2, hc * std::sin(a) * 1.2, 0);
    holes.push_back(rod(c + Vec3(0, 0, zp - m), c + Vec3(0, 0, zp + tp + m), hr, v));
  }
  const double rport = 0.13 * d;
  const Shape port = rod({0, 0, 0.55 * L}, {ro + 0.25 * d, 0, 0.55 * L}, rport, v);
  return {body | (plate - unite(holes)) | port, std::max({L + Lf, 2 * Rf, S * 1.42}), std::min({tf, tp, 2 * hr})};
}

Construction connector(const Params& p, double v) {
  const double d = p("body_d"), r = d / 2, L = p("length_ratio") * d;
  const double s = p("nut_ratio") * d, Ln = p("nut_len_ratio") * d, rt = p("tail_ratio") * r;
  const double Lt = 1.2 * d + 0.02;
  std::vector<Shape> parts{
      rod({0, 0, 0}, {0, 0, L}, r, v),
      Shape::leaf(prim::hex_prism(s, L - 0.2 * Ln, L + 0.8 * Ln)),
      lathe({{0, -0.6 * d}, {rt, -0.6 * d}, {r * 0.9, 0.05 * d}, {0, 0.05 * d}}, r, v),  // strain relief
      rod({0, 0, -Lt}, {0, 0, -0.5 * d}, rt, v)};                                        // cable tail
  const double top = L + 0.8 * Ln, rr = 0.62 * r, m = 2 * v;
  Shape recess = rod({0, 0, top - 0.35 * d}, {0, 0, top + m}, rr, v);
  const int pins = static_cast<int>(p("pins"));
  std::vector<Shape> pin_rods;
  const double rp = std::max(0.06 * d, 1.2 * v);
  for (int k = 0; k < pins; ++k) {
    const double a = 2 * kPi * k / pins;
    const Vec3 c(0.55 * rr * std::cos(a), 0.55 * rr * std::sin(a), 0);
    pin_rods.push_back(rod(c + Vec3(0, 0, top - 0.4 * d), c + Vec3(0, 0, top - 0.08 * d), rp, v));
  }
  return {(unite(parts) - recess) | unite(pin_rods), L + Ln + Lt, std::min(2 * rt, 2 * rp)};
}

Construction grab_bar(const Params& p, double v) {
  const double S = p("span"), d = p("bar_d"), r = d / 2, H = p("standoff_ratio") * S;
  const double bs = p("base_ratio") * d, tp = 0.35 * d, m = 2 * v;
  std::vector<Shape> parts{rod({-S / 2, 0, H}, {S / 2, 0, H}, r, v), ball({-S / 2, 0, H}, r, v), ball({S / 2, 0, H}, r, v)};
  std::vector<Shape> holes;
  for (double x : {-S / 2, S / 2}) {
    parts.push_back(rod({x, 0, 0}, {x, 0, H}, r, v));
    parts.push_back(box({x - bs / 2, -bs, -tp}, {x + bs / 2, bs, 0}));
    for (double y : {-0.65 * bs, 0.65 * bs}) holes.push_back(rod({x, y, -tp - m}, {x, y, m}, 0.15 * bs, v));
  }
  return {unite(parts) - unite(holes), S + bs, std::min(d, tp)};
}

Construction padeye(const Params& p, double v) {
  const double hd = p("hole_d"), W = p("width_ratio") * hd, H = p("height_ratio") * W, t = p("thickness_ratio") * W;
  std::vector<Vec2> poly{{-W / 2, 0}, {W / 2, 0}};
  const int n = 16;
  for (int k = 0; k <= n; ++k) poly.emplace_back(W / 2 * std::cos(kPi * k / n), H + W / 2 * std::sin(kPi * k / n));
  // The polygon lies in (x, z); extrude along y.
  Pose T = Pose::Identity();
  T.linear() << 1, 0, 0, 0, 0, -1, 0, 1, 0;  // (x, y, z) -> (x, -z, y)
  const Shape plate = Shape::leaf(prim::prism(poly, -t / 2, t / 2)).moved(T);
  const double rc = 0.42 * W, tc = 0.3 * t, m = 2 * v;
  const Shape cheeks = rod({0, -t / 2 - tc, H}, {0, t / 2 + tc, H}, rc, v);
  const double bl = 1.5 * W, bw = 2.5 * t + 0.04 * W, bt = 0.6 * t;
  const Shape base = box({-bl / 2, -bw / 2, -bt}, {bl / 2, bw / 2, 0});
  const Shape hole = rod({0, -t / 2 - tc - m, H}, {0, t / 2 + tc + m, H}, hd / 2, v);
  return {(plate | cheeks | base) - hole, std::max(bl, H + W / 2 + bt), std::min(tc, bt)};
}

// --- structure -------------------------------------------------------------------------------
Construction bracket(const Params& p, double v) {
  const double W = p("width"), L1 = p("leg"), L2 = p("leg_ratio") * L1;
  const double t = p("thickness_ratio") * std::max(L1, L2), m = 2 * v;
  const double hr = std::min({p("hole_ratio") * W / 2, 0.25 * (L1 - t), 0.25 * (L2 - t)});
  const bool gusset = p("gusset") == 1;
  std::vector<Shape> parts{box({0, 0, 0}, {L1, W, t}), box({0, 0, 0}, {t, W, L2})};
  if (gusset) {
    const double g1 = 0.55 * (L1 - t), g2 = 0.55 * (L2 - t);
    Pose T = Pose::Identity();
    T.linear() << 1, 0, 0, 0, 0, -1, 0, 1, 0;
    T.translation() = Vec3(0, W / 2, 0);
    parts.push_back(Shape::leaf(prim::prism({{t / 2, t / 2}, {t + g1, t / 2}, {t / 2, t + g2}}, -t / 2, t / 2)).moved(T));
  }
  std::vector<Shape> holes;
  const std::vector<double> ys = gusset ? std::vector<double>{0.25 * W, 0.75 * W} : std::vector<double>{0.5 * W};
  for (double y : ys) {
    holes.push_back(rod({t + 0.55 * (L1 - t), y, -m}, {t + 0.55 * (L1 - t), y, t + m}, hr, v));
    holes.push_back(rod({-m, y, t + 0.55 * (L2 - t)}, {t + m, y, t + 0.55 * (L2 - t)}, hr, v));
  }
  return {unite(parts) - unite(holes), std::max({L1, L2, W}), t};
}

Construction pipe_clamp(const Params& p, double v) {
  const double od = p("pipe_od"), ri = od / 2, t = p("band_t_ratio") * od, ro = ri + t;
  const double bw = p("band_width_ratio") * od, g = p("gap_ratio") * od, Ll = p("lug_ratio") * (0.02 + 0.3 * od);
  const double tl = 1.3 * t, m = 2 * v;
  std::vector<Shape> parts{tube(ri, ro, -bw / 2, bw / 2, v)};
  std::vector<Shape> holes;
  const double hr = std::min(0.3 * Ll, 0.3 * bw);
  for (double sx : {-1.0, 1.0}) {
    for (double sy : {-1.0, 1.0}) {
      const double y0 = sy * g / 2, y1 = sy * (g / 2 + tl);
      const double x0 = sx * (ri + 0.5 * t), x1 = sx * (ro + Ll);
      parts.push_back(box({std::min(x0, x1), std::min(y0, y1), -bw / 2}, {std::max(x0, x1), std::max(y0, y1), bw / 2}));
    }
    const double xh = sx * (ro + 0.55 * Ll);
    holes.push_back(rod({xh, -g / 2 - tl - m, 0}, {xh, g / 2 + tl + m, 0}, hr, v));
  }
  const Shape gap = box({-ro - Ll - m, -g / 2, -bw / 2 - m}, {ro + Ll + m, g / 2, bw / 2 + m});
  return {unite(parts) - gap - unite(holes), 2 * (ro + Ll), std::min({t, g, 2 * hr})};
}

// --- fasteners -------------------------------------------------------------------------------
Construction hex_bolt(const Params& p, double v) {
  const auto& s = kMetric[static_cast<int>(p("size"))];
  const double r = s.d / 2, L = p("length_ratio") * s.d, k = p("head_ratio") * s.k, Rc = s.s / std::sqrt(3.0) * 1.05;
  const double c = 0.08 * s.d;
  const Shape head = Shape::leaf(prim::hex_prism(s.s, 0, k)) &
                     lathe({{0, -k}, {Rc, -k}, {Rc, k - (Rc - 0.48 * s.s) * std::tan(kPi / 6)}, {0.48 * s.s, k}, {0, k}}, Rc, v);
  const Shape shank = lathe({{0, -L}, {r - c, -L}, {r, -L + c}, {r, 0.1 * k}, {0, 0.1 * k}}, r, v);
  return {head | shank, L + k, std::min(k, s.d)};
}

Construction hex_nut(const Params& p, double v) {
  const auto& s = kMetric[2 + static_cast<int>(p("size"))];
  const double af = p("flats_ratio") * s.d, h = p("height_ratio") * s.d, m = 2 * v;
  const Shape nut = Shape::leaf(prim::hex_prism(af, 0, h)) - rod({0, 0, -m}, {0, 0, h + m}, s.d / 2, v);
  return {nut, std::max(af * 2 / std::sqrt(3.0), h), std::min(h, (af - s.d) / 2)};
}

// --- corrosion protection --------------------------------------------------------------------
Construction anode_bar(const Params& p, double v) {
  const double L = p("length"), w = p("width_ratio") * L, h = p("height_ratio") * w;
  const double so = p("standoff"), rc = std::max(0.006, 0.08 * w), e = 0.08 * L + rc;
  // Trapezoid section in (y, z) extruded along x.
  Pose T = Pose::Identity();
  T.linear() << 0, 0, 1, 1, 0, 0, 0, 1, 0;  // (a, b, c) -> (c, a, b): prism z -> x
  const Shape bar = Shape::leaf(prim::prism({{-w / 2, 0}, {w / 2, 0}, {0.35 * w, h}, {-0.35 * w, h}}, -L / 2, L / 2)).moved(T);
  const double zc = 0.4 * h, xe = L / 2 + e, fl = 3.5 * rc, ft = rc;
  std::vector<Shape> parts{bar, rod({-xe, 0, zc}, {xe, 0, zc}, rc, v)};
  for (double sx : {-1.0, 1.0}) {
    parts.push_back(ball({sx * xe, 0, zc}, rc, v));
    parts.push_back(rod({sx * xe, 0, zc}, {sx * xe, 0, -so}, rc, v));
    parts.push_back(box({sx * xe - fl / 2, -fl / 2, -so - ft}, {sx * xe + fl / 2, fl / 2, -so}));
  }
  return {unite(parts), L + 2 * e + fl, std::min(2 * rc, ft)};
}

Construction anode_bracelet(const Params& p, double v) {
  const double od = p("pipe_od"), ri = od / 2, t = p("thickness"), ro = ri + t, w = p("width");
  const double g = p("gap"), c = 0.35 * t, m = 2 * v;
  const Shape shell = lathe({{ri, -w / 2}, {ro - c, -w / 2}, {ro, -w / 2 + c}, {ro, w / 2 - c}, {ro - c, w / 2}, {ri, w / 2}}, ro, v);
  const Shape gap = box({-ro - m, -g / 2, -w / 2 - m}, {ro + m, g / 2, w / 2 + m});
  // Steel tabs welded across each gap.
  const double tw = 0.35 * w, tt = std::max(0.004, 0.15 * t), tl = g + 0.25 * ro;
  std::vector<Shape> tabs;
  for (double sx : {-1.0, 1.0})
    tabs.push_back(box({sx > 0 ? ro - 0.2 * t : -ro - tt, -tl / 2, -tw / 2}, {sx > 0 ? ro + tt : -ro + 0.2 * t, tl / 2, tw / 2}));
  return {(shell - gap) | unite(tabs), std::max(2 * ro + 2 * tt, w), std::min({t, g, tt})};
}

std::vector<Family> make_families() {
  const std::vector<std::string> none_gusset{"none", "gusset"};
  std::vector<Family> f;
  f.push_back({"elbow", "butt-weld pipe elbow, 45 or 90 degrees, with tangent stubs",
               {logu("od", 0.03, 0.25, "pipe outside diameter"), uni("wall_ratio", 0.07, 0.14, "1", "wall / od"),
                uni("bend_ratio", 1.0, 1.6, "1", "bend radius / od"), choice("angle", {"45", "90"}, "bend angle, deg"),
                uni("tangent_ratio", 0.0, 0.6, "1", "straight stub length / od")},
               1.0, elbow});
  f.push_back({"tee", "equal or reducing butt-weld tee",
               {logu("od", 0.03, 0.22, "run outside diameter"), uni("branch_ratio", 0.5, 1.0, "1", "branch od / run od"),
                uni("wall_ratio", 0.07, 0.14, "1", "wall / od"), uni("run_ratio", 1.6, 2.4, "1", "run length / od"),
                uni("height_ratio", 0.8, 1.2, "1", "branch height above the run axis / od")},
               1.0, tee});
  f.push_back({"reducer", "concentric butt-weld reducer",
               {logu("od", 0.04, 0.3, "large-end outside diameter"), uni("ratio", 0.45, 0.8, "1", "small od / large od"),
                uni("wall_ratio", 0.05, 0.11, "1", "wall / large od"), uni("length_ratio", 0.8, 1.5, "1", "length / od"),
                uni("cone_fraction", 0.4, 0.7, "1", "conical part / length")},
               1.0, reducer});
  f.push_back({"end_cap", "ellipsoidal butt-weld pipe cap",
               {logu("od", 0.04, 0.3, "outside diameter"), uni("wall_ratio", 0.05, 0.11, "1", "wall / od"),
                uni("skirt_ratio", 0.1, 0.5, "1", "straight skirt / od"), uni("head_ratio", 0.22, 0.3, "1", "head depth / od")},
               1.0, end_cap});
  f.push_back({"flange_weld_neck", "weld-neck raised-face flange, EN 1092-1 PN16 sizes",
               {choice("dn", flange_labels(), "nominal size"), uni("thickness_ratio", 0.85, 1.25, "1", "thickness / nominal"),
                uni("raised_face", 0.002, 0.004, "m", "raised-face height"), uni("hub_ratio", 0.8, 1.3, "1", "hub length / nominal"),
                uni("wall_ratio", 0.05, 0.1, "1", "neck wall / pipe od")},
               1.0, flange_weld_neck});
  f.push_back({"flange_blind", "blind raised-face flange, EN 1092-1 PN16 sizes",
               {choice("dn", flange_labels(), "nominal size"), uni("thickness_ratio", 0.85, 1.25, "1", "thickness / nominal"),
                uni("raised_face", 0.002, 0.004, "m", "raised-face height"),
                uni("od_ratio", 1.0, 1.08, "1", "outside diameter / EN 1092-1 value")},
               1.0, flange_blind});
  f.push_back({"valve", "flanged ball or gate valve with handwheel or lever",
               {logu("od", 0.03, 0.11, "pipe outside diameter"), choice("kind", {"ball", "gate"}, "body"),
                choice("actuator", {"handwheel", "lever"}, "operator"), uni("length_ratio", 2.6, 3.6, "1", "face-to-face / od"),
                uni("body_ratio", 1.5, 2.2, "1", "body size / od"), uni("stem_ratio", 0.5, 1.2, "1", "stem above body / od"),
                uni("actuator_ratio", 0.6, 1.1, "1", "wheel diameter or lever length / face-to-face")},
               1.0, valve});
  f.push_back({"t_handle", "ROV T-handle (shaft, collar, cross bar)",
               {logu("shaft_d", 0.016, 0.04, "shaft diameter"), uni("shaft_ratio", 4.0, 8.0, "1", "shaft length / diameter"),
                uni("bar_ratio", 3.5, 7.0, "1", "bar length / shaft diameter"), uni("bar_d_ratio", 0.7, 1.0, "1", "bar / shaft diameter"),
                uni("collar_ratio", 1.5, 2.3, "1", "collar / shaft diameter")},
               1.0, t_handle});
  f.push_back({"hot_stab", "hot-stab receptacle: body with blind bore, entry funnel, mounting plate, side port",
               {logu("body_d", 0.05, 0.13, "body diameter"), uni("length_ratio", 1.2, 2.2, "1", "body length / diameter"),
                uni("bore_ratio", 0.35, 0.55, "1", "bore / body diameter"), uni("funnel_ratio", 1.5, 2.1, "1", "funnel mouth / body diameter"),
                uni("plate_ratio", 1.5, 2.0, "1", "plate side / body diameter")},
               1.0, hot_stab});
  f.push_back({"connector", "subsea electrical connector: body, hex coupling nut, pin face, cable tail",
               {logu("body_d", 0.02, 0.07, "body diameter"), uni("length_ratio", 2.0, 4.0, "1", "body length / diameter"),
                uni("nut_ratio", 1.25, 1.6, "1", "nut across flats / body diameter"),
                uni("nut_len_ratio", 0.6, 1.0, "1", "nut length / body diameter"), uni("tail_ratio", 0.35, 0.6, "1", "cable / body diameter"),
                integer("pins", 3, 8, "contact pins")},
               1.0, connector});
  f.push_back({"bracket", "L-bracket with bolt holes, optional gusset",
               {logu("width", 0.04, 0.2, "plate width"), logu("leg", 0.05, 0.3, "horizontal leg"),
                uni("leg_ratio", 0.5, 1.2, "1", "vertical / horizontal leg"), uni("thickness_ratio", 0.05, 0.09, "1", "thickness / longer leg"),
                uni("hole_ratio", 0.15, 0.3, "1", "hole diameter / width"), choice("gusset", none_gusset, "stiffener")},
               1.0, bracket});
  f.push_back({"pipe_clamp", "two half-ring pipe clamp with bolting lugs",
               {logu("pipe_od", 0.03, 0.28, "pipe outside diameter"), uni("band_t_ratio", 0.06, 0.12, "1", "band thickness / od"),
                uni("band_width_ratio", 0.25, 0.5, "1", "band width / od"), uni("gap_ratio", 0.04, 0.08, "1", "gap between halves / od"),
                uni("lug_ratio", 0.6, 1.0, "1", "lug length / (0.02 m + 0.3 od)")},
               1.0, pipe_clamp});
  f.push_back({"hex_bolt", "ISO 4014 hex bolt, plain shank (threads not modelled)",
               {choice("size", metric_labels(0, 8), "thread size"), uni("length_ratio", 3.0, 9.0, "1", "shank length / d"),
                uni("head_ratio", 0.85, 1.2, "1", "head height / ISO 4014 value")},
               1.0, hex_bolt});
  f.push_back({"hex_nut", "hex nut (heavy series), plain bore",
               {choice("size", metric_labels(2, 10), "thread size"), uni("flats_ratio", 1.45, 1.6, "1", "across flats / d"),
                uni("height_ratio", 0.8, 1.0, "1", "height / d")},
               1.0, hex_nut});
  f.push_back({"anode_bar", "stand-off bar anode on a steel core with two feet",
               {logu("length", 0.15, 0.4, "anode length"), uni("width_ratio", 0.12, 0.25, "1", "width / length"),
                uni("height_ratio", 0.6, 1.0, "1", "height / width"), uni("standoff", 0.02, 0.06, "m", "foot below the bar")},
               1.0, anode_bar});
  f.push_back({"anode_bracelet", "pipeline bracelet anode: two tapered half shells joined by tabs",
               {logu("pipe_od", 0.1, 0.4, "pipe outside diameter"), uni("thickness", 0.015, 0.04, "m", "shell thickness"),
                uni("width", 0.06, 0.2, "m", "axial width"), uni("gap", 0.01, 0.03, "m", "gap between shells")},
               1.0, anode_bracelet});
  f.push_back({"grab_bar", "ROV grab bar: round bar on two standoffs with base plates",
               {logu("span", 0.15, 0.42, "distance between standoffs"), logu("bar_d", 0.02, 0.04, "bar diameter"),
                uni("standoff_ratio", 0.2, 0.45, "1", "standoff height / span"), uni("base_ratio", 1.8, 2.8, "1", "base plate / bar diameter")},
               1.0, grab_bar});
  f.push_back({"padeye", "lifting padeye: plate with eye, cheek plates and base plate",
               {logu("hole_d", 0.02, 0.08, "eye diameter"), uni("width_ratio", 2.3, 3.2, "1", "plate width / eye diameter"),
                uni("height_ratio", 0.8, 1.3, "1", "eye height / plate width"), uni("thickness_ratio", 0.25, 0.45, "1", "plate thickness / width")},
               1.0, padeye});
  return f;
}

}  // namespace

// --- Params ----------------------------------------------------------------------------------
double Params::operator()(const std::string& name) const {
  for (std::size_t i = 0; i < specs->size(); ++i)
    if ((*specs)[i].name == name) return values.at(i);
  throw Error("unknown parameter '" + name + "'");
}

std::string Params::value_text(std::size_t i) const {
  const auto& s = (*specs)[i];
  if (s.draw == Draw::Choice) return s.choices.at(static_cast<std::size_t>(values[i]));
  if (s.draw == Draw::Integer) return std::to_string(static_cast<long long>(values[i]));
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", values[i]);
  return buf;
}

std::string Params::text() const {
  std::string t;
  for (std::size_t i = 0; i < values.size(); ++i) {
    const auto& s = (*specs)[i];
    if (i) t += ", ";
    t += s.name + "=" + value_text(i);
    if (s.unit == "m" || s.unit == "deg") t += " " + s.unit;
  }
  return t;
}

const std::vector<Family>& all_families() {
  static const std::vector<Family> families = make_families();
  return families;
}

const Family* find_family(const std::string& name) {
  for (const auto& f : all_families())
    if (f.name == name) return &f;
  return nullptr;
}

Params draw_params(const Family& family, Rng& rng) {
  Params p;
  p.specs = &family.params;
  for (const auto& s : family.params) {
    double x = 0.0;
    switch (s.draw) {
      case Draw::Uniform: x = rng.uniform(s.lo, s.hi); break;
      case Draw::LogUniform: x = std::exp(rng.uniform(std::log(s.lo), std::log(s.hi))); break;
      case Draw::Integer:
      case Draw::Choice: {
        const auto lo = static_cast<std::size_t>(std::llround(s.lo)), hi = static_cast<std::size_t>(std::llround(s.hi));
        x = static_cast<double>(lo + rng.index(hi - lo + 1));
        break;
      }
    }
    p.values.push_back(x);
  }
  return p;
}

Params make_params(const Family& family, std::vector<double> values) {
  if (values.size() != family.params.size())
    throw Error("family '" + family.name + "' takes " + std::to_string(family.params.size()) + " parameters");
  Params p;
  p.specs = &family.params;
  p.values = std::move(values);
  return p;
}

}  // namespace ts::catalogue
