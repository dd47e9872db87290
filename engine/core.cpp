#include "engine/core.hpp"

#include <cmath>
#include <numbers>

namespace ts {

namespace {
std::string format_error(const std::string& message, const std::string& file,
                         const std::string& field) {
  if (file.empty() && field.empty()) return message;
  std::string out = message + " (";
  if (!file.empty()) out += file;
  if (!file.empty() && !field.empty()) out += ", ";
  if (!field.empty()) out += field;
  return out + ")";
}

std::uint64_t splitmix64(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

inline std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
}  // namespace

Error::Error(const std::string& message, const std::string& file, const std::string& field)
    : std::runtime_error(format_error(message, file, field)),
      message_(message), file_(file), field_(field) {}

Rng::Rng(std::uint64_t seed, std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  // Mix the tuple so that (seed, a, b, c) and any permutation give unrelated streams.
  std::uint64_t x = seed;
  std::uint64_t h = splitmix64(x);
  for (std::uint64_t v : {a, b, c}) {
    x ^= v + 0x632be59bd9b4e019ULL + (h << 6) + (h >> 2);
    h = splitmix64(x);
  }
  for (auto& s : s_) s = splitmix64(x);
}

std::uint64_t Rng::next() {
  const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
  const std::uint64_t t = s_[1] << 17;
  s_[2] ^= s_[0];
  s_[3] ^= s_[1];
  s_[1] ^= s_[2];
  s_[0] ^= s_[3];
  s_[2] ^= t;
  s_[3] = rotl(s_[3], 45);
  return result;
}

double Rng::uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

double Rng::uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

std::size_t Rng::index(std::size_t n) {
  // Lemire's nearly divisionless method, with rejection for exact uniformity.
  const std::uint64_t range = static_cast<std::uint64_t>(n);
  __uint128_t m = static_cast<__uint128_t>(next()) * range;
  std::uint64_t low = static_cast<std::uint64_t>(m);
  if (low < range) {
    const std::uint64_t threshold = (0 - range) % range;
    while (low < threshold) {
      m = static_cast<__uint128_t>(next()) * range;
      low = static_cast<std::uint64_t>(m);
    }
  }
  return static_cast<std::size_t>(m >> 64);
}

double Rng::normal() {
  double u1 = uniform();
  while (u1 <= 0.0) u1 = uniform();
  const double u2 = uniform();
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

Vec3 Rng::unit_vector() {
  const double z = uniform(-1.0, 1.0);
  const double phi = uniform(0.0, 2.0 * std::numbers::pi);
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

Eigen::Quaterniond Rng::rotation() {
  const double u1 = uniform(), u2 = uniform(), u3 = uniform();
  const double a = std::sqrt(1.0 - u1), b = std::sqrt(u1);
  const double t2 = 2.0 * std::numbers::pi * u2, t3 = 2.0 * std::numbers::pi * u3;
  Eigen::Quaterniond q(b * std::cos(t3), a * std::sin(t2), a * std::cos(t2), b * std::sin(t3));
  q.normalize();
  return q;
}

}  // namespace ts
