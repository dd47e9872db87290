#include "engine/core.hpp"
#include "io/atomic_file.hpp"
#include "io/h5.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <hdf5.h>
#include <zlib.h>

#include <chrono>
#include <csignal>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>
#include <filesystem>
#include <functional>
#include <thread>

namespace fs = std::filesystem;
namespace h5 = ts::io::h5;
using ts::test::TempDir;

namespace {

std::string numbered(const char* stem, int k) {
  std::string s = stem;
  s += std::to_string(k);  // (not "x" + to_string: GCC 12 warns falsely on that, -Wrestrict)
  return s;
}

// A small file exercising every kind of content the wrapper writes.
void write_sample(const fs::path& path) {
  auto f = h5::File::create(path);
  auto root = f.root();
  root.set_attribute("schema_version", std::int64_t{3});
  root.set_attribute("title", "sample");
  root.set_attribute("weights", std::vector<double>{0.5, 1.5, -2.0});
  auto obj = root.create_group("objects/cube");
  obj.set_attribute("scale", 0.125);
  std::vector<double> pts{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11};
  obj.write("fine/points", pts.data(), {4, 3});
  std::vector<float> feat(2 * 33);
  for (std::size_t i = 0; i < feat.size(); ++i) feat[i] = static_cast<float>(i) * 0.25f;
  obj.write("features", feat.data(), {2, 33}, h5::Storage{.deflate = 4});
  std::vector<std::int32_t> ijk{-1, 0, 1, 2, 3, 4};
  obj.write("field/ijk", ijk.data(), {2, 3});
  obj.write("ids", std::vector<std::int64_t>{7, -8, 9});
  obj.write("flags", std::vector<std::uint8_t>{1, 0, 1, 1});
  root.write_strings("order", {"cube", "sphere", ""});
  root.create_extendible<double>("log/contacts", {3});
  std::vector<double> rows{1, 2, 3, 4, 5, 6};
  root.open_group("log").append("contacts", rows.data(), 2);
  f.close();
}

}  // namespace

TEST_CASE("h5: every type, attribute and group round-trips") {
  TempDir dir("h5");
  const auto p = dir / "a.h5";
  write_sample(p);

  auto f = h5::File::open(p);
  auto root = f.root();
  CHECK(root.int_attribute("schema_version") == 3);
  CHECK(root.string_attribute("title") == "sample");
  CHECK(root.doubles_attribute("weights", 3) == std::vector<double>{0.5, 1.5, -2.0});
  CHECK(root.children() == std::vector<std::string>{"log", "objects", "order"});
  CHECK(root.attributes() == std::vector<std::string>{"schema_version", "title", "weights"});
  CHECK(root.has("objects/cube/fine/points"));
  CHECK_FALSE(root.has("objects/sphere/fine/points"));
  CHECK(root.has_group("objects/cube"));
  CHECK_FALSE(root.has_group("objects/cube/features"));
  CHECK(root.has_dataset("objects/cube/features"));

  auto obj = root.open_group("objects/cube");
  CHECK(obj.path() == "/objects/cube");
  CHECK(obj.double_attribute("scale") == 0.125);
  h5::Shape shape;
  const auto pts = obj.read<double>("fine/points", {h5::kAny, 3}, &shape);
  CHECK(shape == h5::Shape{4, 3});
  REQUIRE(pts.size() == 12);
  for (int i = 0; i < 12; ++i) CHECK(pts[i] == i);
  const auto feat = obj.read<float>("features", {h5::kAny, 33});
  REQUIRE(feat.size() == 66);
  CHECK(feat[65] == 65 * 0.25f);
  CHECK(obj.read<std::int32_t>("field/ijk", {h5::kAny, 3}) == std::vector<std::int32_t>{-1, 0, 1, 2, 3, 4});
  CHECK(obj.read<std::int64_t>("ids", {3}) == std::vector<std::int64_t>{7, -8, 9});
  CHECK(obj.read<std::uint8_t>("flags", {h5::kAny}) == std::vector<std::uint8_t>{1, 0, 1, 1});
  CHECK(root.read_strings("order") == std::vector<std::string>{"cube", "sphere", ""});
  CHECK(root.read<double>("log/contacts", {h5::kAny, 3}) == std::vector<double>{1, 2, 3, 4, 5, 6});
  CHECK(obj.read_rows<double>("fine/points", 1, 2, {h5::kAny, 3}) ==
        std::vector<double>{3, 4, 5, 6, 7, 8});
}

TEST_CASE("h5: extendible datasets grow across reopenings") {
  TempDir dir("h5");
  const auto p = dir / "log.h5";
  {
    auto f = h5::File::create(p);
    f.root().create_extendible<float>("taxels", {2, 2}, h5::Storage{.deflate = 1, .chunk_rows = 2});
    f.close();
  }
  for (int k = 0; k < 3; ++k) {
    auto f = h5::File::open(p, h5::File::Access::read_write);
    std::vector<float> rows(4 * (k + 1));
    for (std::size_t i = 0; i < rows.size(); ++i) rows[i] = static_cast<float>(10 * k + i);
    f.root().append("taxels", rows.data(), static_cast<std::uint64_t>(k + 1));
    f.close();
  }
  auto f = h5::File::open(p);
  h5::Shape s;
  const auto all = f.root().read<float>("taxels", {h5::kAny, 2, 2}, &s);
  CHECK(s == h5::Shape{6, 2, 2});
  CHECK(all[0] == 0.0f);
  CHECK(all[4] == 10.0f);
  CHECK(all[12] == 20.0f);
  CHECK(all[23] == 31.0f);
}

TEST_CASE("h5: shape, type and missing-field errors name the file and the path") {
  TempDir dir("h5");
  const auto p = dir / "db.h5";
  write_sample(p);
  auto f = h5::File::open(p, h5::File::Access::read, "db.h5");
  auto obj = f.group("objects/cube");
  CHECK_THROWS_WITH_AS(obj.read<double>("fine/points", {h5::kAny, 2}),
                       "dataset has shape [4,3], expected [n,2] (db.h5, /objects/cube/fine/points)",
                       ts::Error);
  CHECK_THROWS_WITH_AS(obj.read<double>("fine/points", {h5::kAny}),
                       doctest::Contains("expected [n]"), ts::Error);
  CHECK_THROWS_WITH_AS(obj.read<double>("features", {h5::kAny, 33}),
                       "dataset holds float32 values, expected float64 (db.h5, /objects/cube/features)",
                       ts::Error);
  CHECK_THROWS_WITH_AS(obj.read<std::uint32_t>("field/ijk", {h5::kAny, 3}),
                       doctest::Contains("holds int32 values, expected uint32"), ts::Error);
  CHECK_THROWS_WITH_AS(obj.read<double>("coarse/points", {h5::kAny, 3}),
                       "dataset is missing (db.h5, /objects/cube/coarse/points)", ts::Error);
  CHECK_THROWS_WITH_AS(f.group("objects/sphere"), "group is missing (db.h5, /objects/sphere)",
                       ts::Error);
  CHECK_THROWS_WITH_AS(obj.int_attribute("scale"),
                       doctest::Contains("expected an integer (db.h5, /objects/cube@scale)"), ts::Error);
  CHECK_THROWS_WITH_AS(obj.string_attribute("nope"), doctest::Contains("attribute is missing"),
                       ts::Error);
  CHECK_THROWS_WITH_AS(f.root().doubles_attribute("weights", 4),
                       doctest::Contains("holds 3 values, expected 4"), ts::Error);
  CHECK_THROWS_WITH_AS(obj.read_rows<double>("fine/points", 3, 2, {h5::kAny, 3}),
                       doctest::Contains("out of range"), ts::Error);
}

TEST_CASE("h5: writing over existing objects is refused") {
  TempDir dir("h5");
  auto f = h5::File::create(dir / "w.h5", "w.h5");
  auto root = f.root();
  root.write("x", std::vector<double>{1.0});
  CHECK_THROWS_WITH_AS(root.write("x", std::vector<double>{2.0}),
                       "dataset already exists (w.h5, /x)", ts::Error);
  root.create_group("g");
  CHECK_THROWS_WITH_AS(root.create_group("g"), "group already exists (w.h5, /g)", ts::Error);
  // Attributes are replaced, not duplicated.
  root.set_attribute("a", std::int64_t{1});
  root.set_attribute("a", std::int64_t{2});
  CHECK(root.int_attribute("a") == 2);
}

TEST_CASE("h5: missing, foreign and truncated files give one clear error") {
  TempDir dir("h5");
  CHECK_THROWS_WITH_AS(h5::File::open(dir / "none.h5"), doctest::Contains("file does not exist"),
                       ts::Error);

  const auto text = dir / "foreign.h5";
  ts::test::write_text(text, "this is not HDF5, just text pretending to be a database\n");
  CHECK_THROWS_WITH_AS(h5::File::open(text), doctest::Contains("not an HDF5 file"), ts::Error);

  const auto empty = dir / "empty.h5";
  ts::test::write_text(empty, "");
  CHECK_THROWS_AS(h5::File::open(empty), ts::Error);

  const auto full = dir / "full.h5";
  write_sample(full);
  const auto bytes = ts::test::read_bytes(full);
  const auto cut = dir / "cut.h5";
  ts::test::write_text(cut, bytes.substr(0, bytes.size() / 2));
  CHECK_THROWS_WITH_AS(h5::File::open(cut), doctest::Contains("truncated"), ts::Error);
  CHECK_THROWS_WITH_AS(h5::File::open(cut), doctest::Contains(cut.string().c_str()), ts::Error);
}

TEST_CASE("h5: a file locked by another writer is told apart from a damaged one") {
  // The run store waits out lock contention (report reading while an experiment appends) but
  // must refuse a damaged file at once: HDF5's messages for a bad superblock contain "lock".
  TempDir dir("h5");
  const auto full = dir / "full.h5";
  write_sample(full);
  auto bytes = ts::test::read_bytes(full);
  const auto damaged = dir / "damaged.h5";
  for (std::size_t i = 8; i < 24 && i < bytes.size(); ++i) bytes[i] = '\xff';  // after the signature
  ts::test::write_text(damaged, bytes);
  bool refused = false;
  try {
    (void)h5::File::open(damaged);
  } catch (const ts::Error& e) {
    refused = true;
    INFO(std::string(e.what()));
    CHECK_FALSE(h5::is_lock_contention(e));
  }
  CHECK(refused);

  // Another holder of an exclusive lock (flock on a separate descriptor conflicts even within
  // one process, as with a second process's HDF5 writer).
  const int fd = ::open(full.c_str(), O_RDONLY);
  REQUIRE(fd >= 0);
  REQUIRE(::flock(fd, LOCK_EX | LOCK_NB) == 0);
  bool locked = false;
  try {
    (void)h5::File::open(full);
  } catch (const ts::Error& e) {
    locked = true;
    INFO(std::string(e.what()));
    CHECK(h5::is_lock_contention(e));
  }
  ::close(fd);
  CHECK(locked);
  CHECK_NOTHROW((void)h5::File::open(full));  // free again
}

TEST_CASE("h5: the same content gives identical bytes (no timestamps)") {
  TempDir dir("h5");
  write_sample(dir / "one.h5");
  // HDF5 timestamps have a resolution of one second: wait past it so that a timestamp would show.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  {
    // Through the atomic output, as every store writes.
    ts::io::AtomicOutput out(dir / "two.h5");
    write_sample(out.temp_path());
    out.commit();
  }
  const auto a = ts::test::read_bytes(dir / "one.h5");
  const auto b = ts::test::read_bytes(dir / "two.h5");
  CHECK(a.size() > 1000);
  CHECK(a == b);
}

TEST_CASE("h5: concurrent readers are serialised and read the right data") {
  TempDir dir("h5");
  const auto p = dir / "c.h5";
  {
    auto f = h5::File::create(p);
    for (int k = 0; k < 8; ++k) {
      std::vector<double> v(3000);
      for (std::size_t i = 0; i < v.size(); ++i) v[i] = k * 10000.0 + static_cast<double>(i);
      f.root().write(numbered("d", k), v.data(), {1000, 3});
    }
    f.close();
  }
  auto f = h5::File::open(p);
  const auto root = f.root();
  std::vector<int> ok(8, 0);
  std::vector<std::thread> threads;
  for (int k = 0; k < 8; ++k)
    threads.emplace_back([&, k] {
      bool good = true;
      for (int rep = 0; rep < 20; ++rep) {
        const auto v = root.read<double>(numbered("d", k), {h5::kAny, 3});
        good = good && v.size() == 3000 && v[2999] == k * 10000.0 + 2999.0;
      }
      ok[k] = good;
    });
  for (auto& t : threads) t.join();
  CHECK(ok == std::vector<int>(8, 1));
}

// Not under ThreadSanitizer: its runtime takes over asynchronous signals and, in the forked child
// of a process with threads, never ran the handler (the child exited 0 two seconds after
// raise(), with a sleep loop after it, its temporary file still there).
#if defined(__SANITIZE_THREAD__)
constexpr bool kThreadSanitizer = true;
#else
constexpr bool kThreadSanitizer = false;
#endif

TEST_CASE("atomic output: Ctrl-C (SIGINT) or SIGTERM removes the temporary file, the target stays" *
          doctest::skip(kThreadSanitizer)) {
  TempDir dir("h5");
  ts::test::write_text(dir / "old.h5", "previous content");
  for (int sig : {SIGINT, SIGTERM}) {
    const pid_t child = ::fork();
    REQUIRE(child >= 0);
    if (child == 0) {  // the child writes into a temporary file and is interrupted half-way
      ts::io::remove_temporaries_on_interrupt();  // as the touchstone command does
      ts::io::AtomicOutput out(dir / "old.h5");
      ts::test::write_text(out.temp_path(), "half-written");
      std::raise(sig);
      ::_exit(0);  // not reached: the signal ends the process
    }
    int status = 0;
    REQUIRE(::waitpid(child, &status, 0) == child);
    CHECK(WIFSIGNALED(status));
    CHECK(WTERMSIG(status) == sig);
    for (const auto& e : std::filesystem::directory_iterator(dir.path()))
      CHECK(e.path().filename().string().find(".tmp-" + std::to_string(child)) == std::string::npos);
    CHECK(ts::test::read_bytes(dir / "old.h5") == "previous content");
  }
}

TEST_CASE("h5: strings as h5py writes them (variable-length UTF-8) and ASCII fixed-width read back") {
  TempDir dir("h5");
  const auto path = dir / "py.h5";
  {  // written with the C API the way h5py does: str -> variable-length UTF-8
    const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    REQUIRE(f >= 0);
    const hid_t vl = H5Tcopy(H5T_C_S1);
    H5Tset_size(vl, H5T_VARIABLE);
    H5Tset_cset(vl, H5T_CSET_UTF8);
    const char* names[] = {"bunny", "Stern-Öse", ""};
    const hsize_t n = 3;
    const hid_t space = H5Screate_simple(1, &n, nullptr);
    const hid_t ds = H5Dcreate2(f, "names", vl, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    REQUIRE(H5Dwrite(ds, vl, H5S_ALL, H5S_ALL, H5P_DEFAULT, names) >= 0);
    const hid_t scalar = H5Screate(H5S_SCALAR);
    const char* noise = "underwater";
    const hid_t a = H5Acreate2(f, "noise", vl, scalar, H5P_DEFAULT, H5P_DEFAULT);
    REQUIRE(H5Awrite(a, vl, &noise) >= 0);
    const hid_t ascii = H5Tcopy(H5T_C_S1);  // and a fixed-width ASCII one (other writers)
    H5Tset_size(ascii, 8);
    const hid_t b = H5Acreate2(f, "unit", ascii, scalar, H5P_DEFAULT, H5P_DEFAULT);
    const char unit[8] = "metre";
    REQUIRE(H5Awrite(b, ascii, unit) >= 0);
    for (hid_t id : {a, b}) H5Aclose(id);
    H5Dclose(ds);
    for (hid_t id : {space, scalar}) H5Sclose(id);
    for (hid_t id : {vl, ascii}) H5Tclose(id);
    H5Fclose(f);
  }
  const auto file = h5::File::open(path);
  const auto root = file.root();
  CHECK(root.read_strings("names") == std::vector<std::string>{"bunny", "Stern-Öse", ""});
  CHECK(root.string_attribute("noise") == "underwater");
  CHECK(root.string_attribute("unit") == "metre");
}

TEST_CASE("h5: a dataset declaring more values than the file stores is refused before allocating") {
  TempDir dir("h5");
  const auto path = dir / "huge.h5";
  {  // a chunked dataset of 1e9 x 7 doubles (56 GB declared), nothing written: a few KB of file
    const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    REQUIRE(f >= 0);
    const hsize_t dims[2] = {1000000000, 7}, chunk[2] = {1024, 7};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(dcpl, 2, chunk);
    const hid_t ds = H5Dcreate2(f, "truth", H5T_IEEE_F64LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    REQUIRE(ds >= 0);
    H5Dclose(ds);
    H5Pclose(dcpl);
    H5Sclose(space);
    H5Fclose(f);
  }
  REQUIRE(fs::file_size(path) < 100000);
  const auto file = h5::File::open(path);
  const auto root = file.root();
  CHECK_THROWS_WITH_AS(root.read<double>("truth", {h5::kAny, 7}),
                       doctest::Contains("declares 7000000000 values (56000000000 bytes) but the file stores only"),
                       ts::Error);
  CHECK_THROWS_WITH_AS(root.read<double>("truth", {h5::kAny, 7}), doctest::Contains("/truth)"), ts::Error);
  CHECK_THROWS_WITH_AS(root.read_rows<double>("truth", 0, 2, {h5::kAny, 7}), doctest::Contains("declares"), ts::Error);
}

TEST_CASE("atomic output: two outputs to one target in one process never share a temporary file") {
  TempDir dir("h5");
  ts::io::AtomicOutput a(dir / "out.bin"), b(dir / "out.bin");
  CHECK(a.temp_path() != b.temp_path());
  ts::test::write_text(a.temp_path(), "first");
  ts::test::write_text(b.temp_path(), "second");
  a.commit();
  CHECK(ts::test::read_bytes(dir / "out.bin") == "first");
  CHECK(std::filesystem::exists(b.temp_path()));   // b's work is its own, untouched by a
  b.commit();
  CHECK(ts::test::read_bytes(dir / "out.bin") == "second");
  for (const auto& e : std::filesystem::directory_iterator(dir.path()))
    CHECK(e.path().filename().string().find(".tmp-") == std::string::npos);
  // Nothing written under the temporary name: the commit is one error naming the target.
  ts::io::AtomicOutput c(dir / "sub.bin");
  CHECK_THROWS_WITH_AS(c.commit(), doctest::Contains("sub.bin"), ts::Error);
}

namespace {

/// Values of every row distinct and every byte varied, so that a misplaced byte, row or chunk
/// shows.
template <class T>
std::vector<T> pattern(std::size_t n) {
  std::vector<T> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<T>((i * 2654435761u) % 30011u) - static_cast<T>(1000);
  return v;
}

/// The dataset as libhdf5 itself reads it (H5Dread through its own filter pipeline).
template <class T>
std::vector<T> hdf5_read(const fs::path& path, const char* name, hid_t mem_type, std::size_t n) {
  std::vector<T> out(n);
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  const hid_t ds = H5Dopen2(f, name, H5P_DEFAULT);
  const herr_t r = H5Dread(ds, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data());
  H5Dclose(ds);
  H5Fclose(f);
  REQUIRE(r >= 0);
  return out;
}

/// A [rows, 33] float dataset written with the C API, chunked by chunk_rows, with the filters
/// `filters` sets on its creation property list (as another writer would make it).
void write_floats_with(hid_t file, const char* name, const std::vector<float>& v, hsize_t chunk_rows,
                       const std::function<void(hid_t)>& filters) {
  const hsize_t dims[2] = {v.size() / 33, 33}, chunk[2] = {chunk_rows, 33};
  const hid_t space = H5Screate_simple(2, dims, nullptr);
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_chunk(dcpl, 2, chunk);
  filters(dcpl);
  const hid_t ds = H5Dcreate2(file, name, H5T_IEEE_F32LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  REQUIRE(ds >= 0);
  REQUIRE(H5Dwrite(ds, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()) >= 0);
  H5Dclose(ds);
  H5Pclose(dcpl);
  H5Sclose(space);
}

}  // namespace

TEST_CASE("h5: deflated chunks read as stored and inflated in parallel give exactly HDF5's values") {
  // Group::read inflates the chunks of a [shuffle,] deflate dataset itself (outside the global
  // lock); the oracle is the data written and libhdf5's own H5Dread of the same file.
  TempDir dir("h5");
  const auto p = dir / "z.h5";
  const std::size_t rows = 1000;  // 7 chunks of 150 rows: the last one partial
  const auto i16 = pattern<std::int16_t>(rows * 64);
  const auto f32 = pattern<float>(rows * 33);
  const auto i32 = pattern<std::int32_t>(rows * 3);
  const auto f64 = pattern<double>(rows * 3);
  {
    auto f = h5::File::create(p);
    auto r = f.root();
    for (const bool shuffle : {true, false}) {
      const h5::Storage st{.deflate = 6, .shuffle = shuffle, .chunk_rows = 150};
      const std::string s = shuffle ? "s_" : "n_";
      r.write(s + "i16", i16.data(), {rows, 64}, st);
      r.write(s + "f32", f32.data(), {rows, 33}, st);
      r.write(s + "i32", i32.data(), {rows, 3}, st);
      r.write(s + "f64", f64.data(), {rows, 3}, st);
    }
    r.write("one_chunk", f64.data(), {5, 3}, h5::Storage{.deflate = 1});
    f.close();
  }
  const auto oracle_s = hdf5_read<float>(p, "s_f32", H5T_NATIVE_FLOAT, f32.size());
  const auto oracle_n = hdf5_read<float>(p, "n_f32", H5T_NATIVE_FLOAT, f32.size());
  CHECK(oracle_s == f32);
  const auto f = h5::File::open(p);
  const auto r = f.root();
  for (const std::string s : {"s_", "n_"}) {
    CAPTURE(s);
    CHECK(r.read<std::int16_t>(s + "i16", {h5::kAny, 64}) == i16);
    CHECK(r.read<float>(s + "f32", {h5::kAny, 33}) == f32);
    CHECK(r.read<std::int32_t>(s + "i32", {h5::kAny, 3}) == i32);
    CHECK(r.read<double>(s + "f64", {h5::kAny, 3}) == f64);
    CHECK(r.read<float>(s + "f32", {h5::kAny, 33}) == (s == "s_" ? oracle_s : oracle_n));
  }
  CHECK(r.read<double>("one_chunk", {5, 3}) == std::vector<double>(f64.begin(), f64.begin() + 15));

  // Many threads at once (thread-local decompressors, chunks inflated in parallel).
  std::vector<int> ok(6, 0);
  std::vector<std::thread> threads;
  for (int k = 0; k < 6; ++k)
    threads.emplace_back([&, k] {
      bool good = true;
      for (int rep = 0; rep < 10; ++rep)
        good = good && (k % 2 ? r.read<std::int16_t>("s_i16", {h5::kAny, 64}) == i16
                              : r.read<float>("n_f32", {h5::kAny, 33}) == f32);
      ok[k] = good;
    });
  for (auto& t : threads) t.join();
  CHECK(ok == std::vector<int>(6, 1));
}

TEST_CASE("h5: a damaged deflated chunk is one clear error, and other filters are read by HDF5") {
  TempDir dir("h5");
  const auto p = dir / "d.h5";
  const auto v = pattern<float>(600 * 33);
  {
    auto f = h5::File::create(p);
    f.root().write("good", v.data(), {600, 33}, h5::Storage{.deflate = 4, .chunk_rows = 200});
    f.root().write("bad", v.data(), {600, 33}, h5::Storage{.deflate = 4, .chunk_rows = 200});
    f.root().write("short", v.data(), {600, 33}, h5::Storage{.deflate = 4, .shuffle = false, .chunk_rows = 200});
    f.close();
  }
  {  // chunk 1 of "bad" replaced by bytes that are no zlib stream; a fletcher32 dataset beside
    const hid_t f = H5Fopen(p.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t ds = H5Dopen2(f, "bad", H5P_DEFAULT);
    std::vector<unsigned char> junk(700, 0x5a);
    const hsize_t offset[2] = {200, 0};
    REQUIRE(H5Dwrite_chunk(ds, H5P_DEFAULT, 0, offset, junk.size(), junk.data()) >= 0);
    H5Dclose(ds);
    // "short": chunk 0 a valid zlib stream of 1 000 bytes where the chunk holds 200 x 33 floats
    const hid_t ds3 = H5Dopen2(f, "short", H5P_DEFAULT);
    std::vector<unsigned char> plain(1000, 7), packed(2000);
    uLongf packed_size = packed.size();
    REQUIRE(compress2(packed.data(), &packed_size, plain.data(), plain.size(), 6) == Z_OK);
    const hsize_t zero[2] = {0, 0};
    REQUIRE(H5Dwrite_chunk(ds3, H5P_DEFAULT, 0, zero, packed_size, packed.data()) >= 0);
    H5Dclose(ds3);
    write_floats_with(f, "checked", v, 64, [](hid_t dcpl) {
      H5Pset_fletcher32(dcpl);
      H5Pset_deflate(dcpl, 3);
    });
    H5Fclose(f);
  }
  const auto f = h5::File::open(p);
  const auto r = f.root();
  CHECK(r.read<float>("good", {h5::kAny, 33}) == v);
  CHECK_THROWS_WITH_AS(r.read<float>("bad", {h5::kAny, 33}), doctest::Contains("/bad"), ts::Error);
  CHECK_THROWS_WITH_AS(r.read<float>("bad", {h5::kAny, 33}), doctest::Contains("d.h5"), ts::Error);
  CHECK_THROWS_WITH_AS(r.read<float>("short", {h5::kAny, 33}), doctest::Contains("/short"), ts::Error);
  CHECK(r.read<float>("checked", {h5::kAny, 33}) == v);
}

TEST_CASE("h5: a deflated dataset whose partial edge chunk is stored unfiltered reads as HDF5 reads it") {
  // H5D_CHUNK_DONT_FILTER_PARTIAL_CHUNKS (other writers, file format 1.10): the fast path must
  // leave such a dataset to HDF5, not take the raw edge chunk for a damaged zlib stream.
  TempDir dir("h5");
  const auto p = dir / "partial.h5";
  const auto v = pattern<float>(5 * 33);
  {
    const hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
    REQUIRE(H5Pset_libver_bounds(fapl, H5F_LIBVER_V110, H5F_LIBVER_LATEST) >= 0);
    const hid_t f = H5Fcreate(p.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl);
    REQUIRE(f >= 0);
    write_floats_with(f, "v", v, 4, [](hid_t dcpl) {
      H5Pset_shuffle(dcpl);
      H5Pset_deflate(dcpl, 4);
      REQUIRE(H5Pset_chunk_opts(dcpl, H5D_CHUNK_DONT_FILTER_PARTIAL_CHUNKS) >= 0);
    });
    H5Fclose(f);
    H5Pclose(fapl);
  }
  const auto f = h5::File::open(p);
  CHECK(f.root().read<float>("v", {5, 33}) == v);
}
