#include "engine/touch/tactile.hpp"
#include "engine/detail.hpp"

#include <algorithm>
#include <cmath>

namespace ts {
inline namespace touch {

namespace {
using detail::require;
// Slope of the linear part of the rising branch: f(cp) = s (ck + cp) / 2 = 1.
double rise_slope(const SensorSettings& s) {
  return 2.0 / (s.knee_compression + s.peak_compression);
}

// Rising branch inverse: c in [0, cp] from r in [0, 1].
double invert_rising(const SensorSettings& s, double r) {
  const double slope = rise_slope(s), ck = s.knee_compression;
  const double w = s.peak_compression - ck;
  if (r <= slope * ck) return r / slope;
  // s ck + s u - s u^2 / (2 w) = r  ->  u = w (1 - sqrt(1 - 2 (r / s - ck) / w))
  const double radicand = std::clamp(1.0 - 2.0 * (r / slope - ck) / w, 0.0, 1.0);
  return ck + w * (1.0 - std::sqrt(radicand));
}

// Falling branch inverse: c in [cp, 1] from r in [f_end, 1].
double invert_falling(const SensorSettings& s, double r) {
  const double v = std::sqrt(std::clamp((1.0 - r) / (1.0 - s.end_response), 0.0, 1.0));
  return s.peak_compression + v * (1.0 - s.peak_compression);
}

}  // namespace

Vec3 SensorSettings::sensel_position(int j) const {
  const int r = j / cols, c = j % cols;
  return {(r - 0.5 * (rows - 1)) * pitch_x, (c - 0.5 * (cols - 1)) * pitch_y, 0.0};
}

void validate(const SensorSettings& s, const std::string& file) {
  require(s.rows > 0 && s.cols > 0 && s.rows * s.cols <= 65536,
          "sensor grid must have 1..65536 sensels", file, "sensor.rows/cols");
  require(s.pitch_x > 0 && s.pitch_y > 0 && std::isfinite(s.pitch_x) && std::isfinite(s.pitch_y),
          "sensel pitch must be positive", file, "sensor.pitch_m");
  require(s.size_x > 0 && s.size_y > 0 && std::isfinite(s.size_x) && std::isfinite(s.size_y),
          "pad size must be positive", file, "sensor.size_m");
  require((s.rows - 1) * s.pitch_x <= s.size_x + 1e-12 && (s.cols - 1) * s.pitch_y <= s.size_y + 1e-12,
          "sensel grid does not fit on the pad", file, "sensor.pitch_m");
  require(s.foam_thickness > 0 && s.foam_thickness < 0.1, "foam thickness must be in (0, 0.1) m",
          file, "sensor.foam_thickness_m");
  require(s.knee_compression > 0 && s.knee_compression < s.peak_compression &&
              s.peak_compression < 1.0,
          "response needs 0 < knee < peak < 1", file, "sensor.response");
  require(s.end_response > 0 && s.end_response < 1, "end_response must be in (0, 1)", file,
          "sensor.response.end_response");
  require(s.signal_peak > 0 && s.signal_peak <= s.signal_full_scale &&
              std::isfinite(s.signal_full_scale),
          "need 0 < signal_peak <= signal_full_scale", file, "sensor.signal_peak");
  require(s.threshold > 0 && s.threshold < 1, "threshold must be in (0, 1)", file,
          "sensor.threshold");
}

double sensor_response(const SensorSettings& s, double c) {
  if (!(c > 0.0)) return 0.0;  // also NaN
  c = std::min(c, 1.0);
  const double slope = rise_slope(s), ck = s.knee_compression, cp = s.peak_compression;
  if (c <= ck) return slope * c;
  if (c <= cp) {
    const double u = c - ck;
    return slope * c - slope * u * u / (2.0 * (cp - ck));
  }
  const double v = (c - cp) / (1.0 - cp);
  return 1.0 - (1.0 - s.end_response) * v * v;
}

double sensel_signal(const SensorSettings& s, double gain, double compression_m) {
  const double e = gain * s.signal_peak * sensor_response(s, compression_m / s.foam_thickness);
  return std::clamp(e, 0.0, s.signal_full_scale);
}

SenselReading invert_sensel(const SensorSettings& s, double gain, double signal, FoldHint hint) {
  SenselReading out;
  out.height = s.foam_thickness;
  if (!std::isfinite(signal) || signal < 0.0 || !(gain > 0.0) || !std::isfinite(gain)) {
    out.flags = kSenselInvalid;
    return out;
  }
  const double peak = gain * s.signal_peak;
  const double r = signal / peak;
  out.contact = r > s.threshold || hint == FoldHint::past_peak;
  if (!out.contact) return out;

  double c = 0.0;
  if (r >= 1.0) {
    c = s.peak_compression;
    out.flags |= kSenselAtPeak;
  } else if (hint == FoldHint::past_peak) {
    if (r < s.end_response) out.flags |= kSenselClamped;
    c = invert_falling(s, r);
  } else if (hint == FoldHint::rising || r < s.end_response) {
    c = invert_rising(s, r);
  } else {
    c = invert_rising(s, r);
    out.alternative = invert_falling(s, r) * s.foam_thickness;
    out.flags |= kSenselAmbiguous;
  }
  out.compression = c * s.foam_thickness;
  out.height = s.foam_thickness - out.compression;
  return out;
}

}  // namespace touch
}  // namespace ts
