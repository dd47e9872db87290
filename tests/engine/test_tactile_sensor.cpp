// Sensor model (Section 3.2, Figure 7) and its inverse (Eq. 1): the fold on both sides of the
// peak, the 10 % threshold, per-sensel gains, and no NaN on any input.
#include "engine/touch/tactile.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <limits>

using namespace ts;

TEST_CASE("response rises to a peak at 80 % of the foam, then falls (Figure 7)") {
  SensorSettings s;
  CHECK(sensor_response(s, 0.0) == 0.0);
  CHECK(sensor_response(s, s.peak_compression) == doctest::Approx(1.0));
  CHECK(sensor_response(s, 1.0) == doctest::Approx(s.end_response));
  double prev = -1.0;
  for (int i = 0; i <= 800; ++i) {  // strictly rising up to the peak
    const double f = sensor_response(s, i * 0.001);
    CHECK(f > prev);
    CHECK(f <= 1.0 + 1e-12);
    prev = f;
  }
  for (int i = 801; i <= 1000; ++i) {  // strictly falling after it
    const double f = sensor_response(s, i * 0.001);
    CHECK(f < prev);
    prev = f;
  }
  // Linear in the working range: Eq. 1's interpolation is exact there.
  const double slope = 2.0 / (s.knee_compression + s.peak_compression);
  CHECK(sensor_response(s, 0.3) == doctest::Approx(0.3 * slope));
  // Continuous (no jump) at the knee and the peak.
  for (double c : {s.knee_compression, s.peak_compression})
    CHECK(std::abs(sensor_response(s, c + 1e-9) - sensor_response(s, c - 1e-9)) < 1e-8);
}

TEST_CASE("signals on both sides of the peak invert to the right compression with the hint") {
  SensorSettings s;
  for (double gain : {0.8, 1.0, 1.17}) {
    for (int i = 75; i <= 1000; i += 7) {  // above the 10 % threshold
      const double c = i * 0.001 * s.foam_thickness;  // m
      const double e = sensel_signal(s, gain, c);
      const bool beyond = c > s.peak_compression * s.foam_thickness;
      const auto r = invert_sensel(s, gain, e, beyond ? FoldHint::past_peak : FoldHint::rising);
      REQUIRE(r.contact);
      CHECK(std::isfinite(r.compression));
      // Exact away from the peak; within 0.1 mm right at it (zero slope: the inverse is
      // continuous but sqrt-sensitive to round-off there).
      CHECK(std::abs(r.compression - c) < 1e-4);
      if (std::abs(c / s.foam_thickness - s.peak_compression) > 0.02)
        CHECK(std::abs(r.compression - c) < 1e-9);
      CHECK(r.height == doctest::Approx(s.foam_thickness - r.compression));
      CHECK((r.flags & kSenselAmbiguous) == 0);
    }
  }
}

TEST_CASE("without a hint: unique below the end response, flagged ambiguous above it") {
  SensorSettings s;
  const double T = s.foam_thickness;
  // Below f_end x peak only the rising branch can produce the signal.
  const double c_low = 0.3 * T;
  auto r = invert_sensel(s, 1.0, sensel_signal(s, 1.0, c_low), FoldHint::unknown);
  CHECK(r.flags == 0);
  CHECK(r.compression == doctest::Approx(c_low).epsilon(1e-9));
  // Beyond the peak: the same signal as a rising compression; flagged, both pre-images given.
  const double c_high = 0.93 * T;
  const double e = sensel_signal(s, 1.0, c_high);
  r = invert_sensel(s, 1.0, e, FoldHint::unknown);
  CHECK((r.flags & kSenselAmbiguous) != 0);
  CHECK(r.compression < s.peak_compression * T);
  CHECK(r.alternative == doctest::Approx(c_high).epsilon(1e-9));
  CHECK(sensel_signal(s, 1.0, r.compression) == doctest::Approx(e).epsilon(1e-9));
  // And a rising compression in the ambiguous band is flagged too, with the truth as its value.
  const double c_mid = 0.7 * T;
  r = invert_sensel(s, 1.0, sensel_signal(s, 1.0, c_mid), FoldHint::unknown);
  CHECK((r.flags & kSenselAmbiguous) != 0);
  CHECK(r.compression == doctest::Approx(c_mid).epsilon(1e-9));
  CHECK(r.alternative > s.peak_compression * T);
}

TEST_CASE("the inverse is stable near the fold and at saturation") {
  SensorSettings s;
  const double T = s.foam_thickness, peak = s.signal_peak;
  // Signals approaching the peak from below converge monotonically to the peak compression.
  double prev = 0.0;
  for (double frac : {0.95, 0.99, 0.999, 0.99999, 1.0}) {
    const auto r = invert_sensel(s, 1.0, frac * peak, FoldHint::rising);
    CHECK(r.compression >= prev);
    CHECK(r.compression <= s.peak_compression * T + 1e-12);
    prev = r.compression;
  }
  CHECK(prev == doctest::Approx(s.peak_compression * T));
  // 1 % of signal noise at the peak moves the result by less than a quarter millimetre.
  for (FoldHint h : {FoldHint::rising, FoldHint::past_peak, FoldHint::unknown}) {
    const auto r = invert_sensel(s, 1.0, 0.99 * peak, h);
    CHECK(std::abs(r.compression - s.peak_compression * T) < 0.25e-3);
  }
  // Over the peak (noise): the peak compression, flagged.
  auto r = invert_sensel(s, 1.0, 1.2 * peak, FoldHint::rising);
  CHECK((r.flags & kSenselAtPeak) != 0);
  CHECK(r.compression == doctest::Approx(s.peak_compression * T));
  // Past peak but below the full-compression response (noise): full compression, flagged.
  r = invert_sensel(s, 1.0, 0.3 * peak, FoldHint::past_peak);
  CHECK((r.flags & kSenselClamped) != 0);
  CHECK(r.compression == doctest::Approx(T));
  CHECK(r.height == doctest::Approx(0.0));
}

TEST_CASE("the 10 % threshold is relative to each sensel's calibrated peak") {
  SensorSettings s;
  for (double gain : {0.7, 1.0, 1.3}) {
    const double thr = 0.1 * gain * s.signal_peak;
    CHECK_FALSE(invert_sensel(s, gain, 0.999 * thr, FoldHint::unknown).contact);
    CHECK(invert_sensel(s, gain, 1.001 * thr, FoldHint::unknown).contact);
  }
  // A sensel known to be past the peak is a contact whatever its signal.
  CHECK(invert_sensel(s, 1.0, 0.0, FoldHint::past_peak).contact);
  // The calibration matters: the same signal means a deeper compression for a weaker sensel.
  const auto weak = invert_sensel(s, 0.8, 100.0, FoldHint::rising);
  const auto strong = invert_sensel(s, 1.2, 100.0, FoldHint::rising);
  CHECK(weak.compression > strong.compression);
}

TEST_CASE("bad signals give flagged readings, never NaN") {
  SensorSettings s;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (double e : {nan, inf, -inf, -1.0}) {
    const auto r = invert_sensel(s, 1.0, e, FoldHint::unknown);
    CHECK_FALSE(r.contact);
    CHECK((r.flags & kSenselInvalid) != 0);
    CHECK(std::isfinite(r.compression));
    CHECK(std::isfinite(r.height));
  }
  for (double g : {0.0, -1.0, nan}) {
    const auto r = invert_sensel(s, g, 100.0, FoldHint::unknown);
    CHECK((r.flags & kSenselInvalid) != 0);
    CHECK_FALSE(r.contact);
  }
  for (double e = 0.0; e <= s.signal_full_scale; e += 0.37)
    for (FoldHint h : {FoldHint::unknown, FoldHint::rising, FoldHint::past_peak}) {
      const auto r = invert_sensel(s, 1.0, e, h);
      REQUIRE(std::isfinite(r.compression));
      REQUIRE(r.compression >= 0.0);
      REQUIRE(r.compression <= s.foam_thickness);
    }
  CHECK(sensel_signal(s, 1.0, nan) == 0.0);
  CHECK(sensel_signal(s, 5.0, 0.003) == s.signal_full_scale);  // the camera saturates
}

TEST_CASE("sensel layout and settings validation") {
  SensorSettings s;
  CHECK(s.sensels() == 72);
  CHECK(s.sensel_position(0).x() == doctest::Approx(-0.0275));
  CHECK(s.sensel_position(0).y() == doctest::Approx(-0.0125));
  CHECK(s.sensel_position(71).x() == doctest::Approx(0.0275));
  CHECK(s.sensel_position(71).y() == doctest::Approx(0.0125));
  CHECK(s.sensel_position(7).x() == doctest::Approx(-0.0225));  // row 1, col 1
  CHECK(s.sensel_position(7).y() == doctest::Approx(-0.0075));
  CHECK_NOTHROW(validate(s));
  SensorSettings bad = s;
  bad.knee_compression = 0.9;
  CHECK_THROWS_AS(validate(bad, "g.json"), Error);
  bad = s;
  bad.pitch_x = 0.01;  // 11 x 10 mm does not fit on 60 mm
  CHECK_THROWS_AS(validate(bad), Error);
  bad = s;
  bad.signal_peak = 300;
  CHECK_THROWS_AS(validate(bad), Error);
}
