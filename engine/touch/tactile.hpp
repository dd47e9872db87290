// Fiber-optic tactile array model (Section 3.2, Figure 7) and its inverse (Eq. 1).
//
// A pad is a grid of sensels on a rigid base covered by a foam layer of thickness z_max. The
// pad frame L has its origin at the centre of the base plane, z along the outward normal (into
// the foam, toward the object) and x along the pad's length. Sensel j sits at (x_j, y_j) and
// measures the compression of the foam column in front of it.
//
// Response (Figure 7): the signal rises with compression, linearly at first (the paper's Eq. 1),
// rounds off to a peak at `peak_compression` (80 % of the thickness) and then falls to
// `end_response` x peak at full compression. With c the compression as a fraction of z_max,
// cp the peak, ck the knee and s = 2 / (ck + cp):
//     f(c) = s c                                   c <= ck
//     f(c) = s c - s (c - ck)^2 / (2 (cp - ck))    ck < c <= cp      (f(cp) = 1, f'(cp) = 0)
//     f(c) = 1 - (1 - f_end) ((c - cp) / (1 - cp))^2   cp < c <= 1   (f(1) = f_end)
// and the calibrated signal of sensel j is e_j = g_j * signal_peak * f(c) (g_j: its gain).
//
// The fold. A signal below f_end x peak can only come from the rising branch: it inverts
// uniquely. A signal between f_end x peak and the peak has two pre-images, one on each side of
// the peak. A single image cannot tell them apart, so the inverse takes a per-sensel hint: the
// "past peak" flag, which the gripper's preprocessor derives from the sensel's time series while
// the fingers close (the signal rose to the peak level and then dropped; compression grows
// monotonically during a grasp). We chose this over neighbouring sensels (a contact patch can
// sit entirely beyond the peak, so neighbours do not disambiguate reliably) and over the finger
// force (one force-torque sensor per finger cannot say which sensel carries the load).
//   hint = rising     -> rising branch        hint = past_peak -> falling branch
//   hint = unknown    -> unique when below f_end x peak; otherwise the rising-branch value
//                        (the paper's Eq. 1 reading, the contact nearest the foam surface),
//                        flagged `ambiguous`, with the falling-branch value in `alternative`.
// Signals at or above the peak invert to the peak compression (continuous in the signal, so
// noise near the peak moves the result by a bounded amount). The inverse never returns NaN:
// a non-finite or negative signal gives an `invalid` reading without contact.
#pragma once

#include "engine/core.hpp"

#include <cstdint>

namespace ts {
inline namespace touch {

/// Geometry and response of one tactile pad (all pads of a gripper share it).
struct SensorSettings {
  int rows = 12;                    ///< sensels along the pad's x axis (its length)
  int cols = 6;                     ///< sensels along the pad's y axis (its width)
  double pitch_x = 0.005;           ///< m, sensel spacing along x
  double pitch_y = 0.005;           ///< m, sensel spacing along y
  double size_x = 0.060;            ///< m, pad base length (x)
  double size_y = 0.030;            ///< m, pad base width (y)
  double foam_thickness = 0.004;    ///< m, z_max of Eq. 1
  double peak_compression = 0.8;    ///< fraction of z_max where the response peaks (Figure 7)
  double knee_compression = 0.6;    ///< fraction of z_max where the linear rise rounds off
  double end_response = 0.6;        ///< response at full compression, as a fraction of the peak
  double signal_peak = 200.0;       ///< signal at the peak for gain 1 (e_max of Eq. 1)
  double signal_full_scale = 255.0; ///< largest signal a tactile image can hold (8-bit camera)
  double threshold = 0.1;           ///< contact threshold, fraction of the sensel's peak (paper: 10 %)

  int sensels() const { return rows * cols; }
  /// Sensel j = row * cols + col at (x_j, y_j, 0) in the pad frame.
  Vec3 sensel_position(int j) const;
};

/// Throws ts::Error (field named) when the settings are inconsistent: non-positive sizes,
/// sensels outside the pad, 0 < knee < peak < 1 violated, end_response outside (0, 1),
/// signal_peak above signal_full_scale, threshold outside (0, 1).
void validate(const SensorSettings& s, const std::string& file = {});

/// What the log knows about each sensel's side of the fold.
enum class FoldHint : std::uint8_t {
  unknown = 0,    ///< no information (logs without a past-peak dataset)
  rising = 1,     ///< compression never passed the peak during this grasp
  past_peak = 2,  ///< compression passed the peak (signal rose to the peak, then fell)
};

/// Flags of a sensel reading.
enum SenselFlag : std::uint8_t {
  kSenselAmbiguous = 1,  ///< two pre-images and no hint: rising-branch value returned
  kSenselAtPeak = 2,     ///< signal at or above the calibrated peak: peak compression returned
  kSenselClamped = 4,    ///< signal inconsistent with the hint (below f_end when past peak)
  kSenselInvalid = 8,    ///< NaN, infinite or negative signal, or non-positive gain
};

struct SenselReading {
  bool contact = false;        ///< above threshold (or past peak)
  double compression = 0.0;    ///< m, foam compression (never NaN)
  double height = 0.0;         ///< m, z_j of Eq. 1: contact height above the base
  double alternative = 0.0;    ///< m, the other pre-image's compression when ambiguous
  std::uint8_t flags = 0;      ///< SenselFlag bits
};

/// Normalized response f(c) for c = compression / z_max (clamped to [0, 1]).
double sensor_response(const SensorSettings& s, double c);

/// Forward model: the signal of a sensel with `gain` at compression `compression_m`, clamped to
/// [0, signal_full_scale] as the camera would.
double sensel_signal(const SensorSettings& s, double gain, double compression_m);

/// Inverse (Eq. 1, calibrated): compression and contact height from a signal. See the file
/// comment for the treatment of the fold. Never NaN.
SenselReading invert_sensel(const SensorSettings& s, double gain, double signal, FoldHint hint);

/// Contact point in the pad frame (x_j, y_j, z_j) for a reading of sensel j.
inline Vec3 sensel_contact(const SensorSettings& s, int j, const SenselReading& r) {
  Vec3 p = s.sensel_position(j);
  p.z() = r.height;
  return p;
}

}  // namespace touch
}  // namespace ts
