#include "experiments/runs/mpi_runs.hpp"

#include "experiments/allocator.hpp"
#include "io/run_store.hpp"

#include <nlohmann/json.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <iostream>
#include <mutex>
#include <thread>

#ifdef TS_HAVE_MPI
#define OMPI_SKIP_MPICXX 1   // the C API only (the deprecated C++ bindings need libmpi_cxx)
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace ts::experiments {

std::filesystem::path rank_folder(const std::filesystem::path& out) {
  return std::filesystem::path(out.string() + ".ranks");
}

std::filesystem::path rank_store(const std::filesystem::path& out, int rank) {
  return rank_folder(out) / ("rank-" + std::to_string(rank) + ".h5");
}

std::vector<std::filesystem::path> rank_stores(const std::filesystem::path& out) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  const auto dir = rank_folder(out);
  if (!std::filesystem::is_directory(dir, ec)) return files;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.starts_with("rank-") && name.ends_with(".h5") && e.is_regular_file()) files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

namespace {

/// FNV-1a, 64 bits: the same on every machine (unlike std::hash).
struct Fnv {
  std::uint64_t h = 1469598103934665603ull;
  void bytes(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  }
  void text(const std::string& s) {
    integer(static_cast<std::int64_t>(s.size()));
    bytes(s.data(), s.size());
  }
  void integer(std::int64_t v) {
    unsigned char b[8];
    for (int i = 0; i < 8; ++i) b[i] = static_cast<unsigned char>((static_cast<std::uint64_t>(v) >> (8 * i)) & 0xff);
    bytes(b, 8);
  }
};

}  // namespace

std::uint64_t plan_fingerprint(const io::RunStoreHeader& header, const std::vector<RunTask>& todo) {
  Fnv f;
  f.text(header.config_json);
  // The database by its content (its path may differ between nodes that mount one file system
  // at different places).
  const auto db = nlohmann::json::parse(header.database_json, nullptr, false);
  f.text(!db.is_discarded() && db.contains("fingerprint") ? db["fingerprint"].dump() : header.database_json);
  f.integer(header.steps);
  for (const auto* list : {&header.variant_configs, &header.objects, &header.database_objects, &header.stages,
                           &header.step_values}) {
    f.integer(static_cast<std::int64_t>(list->size()));
    for (const auto& s : *list) f.text(s);
  }
  f.integer(static_cast<std::int64_t>(todo.size()));
  for (const RunTask& t : todo) {
    f.integer(t.variant);
    f.integer(t.object);
    f.integer(t.run);
  }
  return f.h;
}

#ifdef TS_HAVE_MPI

namespace {

constexpr int kRequest = 1, kReply = 2, kDone = 3;

/// The calls into MPI of one process, one at a time (MPI_THREAD_SERIALIZED).
std::mutex& mpi_mutex() {
  static std::mutex m;
  return m;
}

}  // namespace

bool mpi_built() { return true; }

MpiSession::MpiSession() {
  int provided = 0;
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided);
  if (provided < MPI_THREAD_SERIALIZED) {
    MPI_Finalize();
    throw Error("the MPI library does not provide MPI_THREAD_SERIALIZED", {}, "--mpi");
  }
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

MpiSession::~MpiSession() { MPI_Finalize(); }

void MpiSession::barrier() {
  std::lock_guard<std::mutex> lock(mpi_mutex());
  MPI_Barrier(MPI_COMM_WORLD);
}

void MpiSession::abort(int code) { MPI_Abort(MPI_COMM_WORLD, code); std::abort(); }

bool MpiSession::same_on_every_rank(std::uint64_t value) {
  std::lock_guard<std::mutex> lock(mpi_mutex());
  std::uint64_t lo = 0, hi = 0;
  MPI_Allreduce(&value, &lo, 1, MPI_UINT64_T, MPI_MIN, MPI_COMM_WORLD);
  MPI_Allreduce(&value, &hi, 1, MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD);
  return lo == hi;
}

DriveOutcome MpiSession::drive(RunEngine& engine, const std::vector<RunTask>& todo,
                               const std::filesystem::path& store, int threads, const DriveSettings& settings) {
  DriveOutcome outcome;
  const auto n = static_cast<std::int64_t>(todo.size());
  std::atomic<std::int64_t> next{0};   // rank 0: the next run of `todo` to hand out
  // Rank 0's dispatcher: answers the other ranks' requests until each has said it is done.
  // It polls (MPI_Iprobe, then sleeps 2 ms: a run takes seconds) instead of blocking in a receive, which in Open MPI
  // spins a core.
  std::thread dispatcher;
  if (rank_ == 0 && size_ > 1) {
    dispatcher = std::thread([&] {
      int done = 0;
      while (done < size_ - 1) {
        int flag = 0;
        MPI_Status status;
        {
          std::lock_guard<std::mutex> lock(mpi_mutex());
          MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &status);
          if (flag) {
            std::int64_t dummy = 0;
            MPI_Recv(&dummy, 1, MPI_INT64_T, status.MPI_SOURCE, status.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            if (status.MPI_TAG == kDone) {
              ++done;
            } else {
              const std::int64_t index = next.fetch_add(1);
              MPI_Send(&index, 1, MPI_INT64_T, status.MPI_SOURCE, kReply, MPI_COMM_WORLD);
            }
          }
        }
        if (!flag) std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    });
  }
  auto take = [&]() -> std::int64_t {
    if (rank_ == 0) return next.fetch_add(1);
    std::lock_guard<std::mutex> lock(mpi_mutex());
    std::int64_t ask = 0, index = 0;
    MPI_Send(&ask, 1, MPI_INT64_T, 0, kRequest, MPI_COMM_WORLD);
    // Wait by polling too (a blocking receive would spin a core while rank 0 answers others).
    int flag = 0;
    MPI_Request req;
    MPI_Irecv(&index, 1, MPI_INT64_T, 0, kReply, MPI_COMM_WORLD, &req);
    while (MPI_Test(&req, &flag, MPI_STATUS_IGNORE) == MPI_SUCCESS && !flag)
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    return index;
  };
  std::mutex store_mutex;
  auto stopped = [&] { return settings.stop && settings.stop->load(); };
  std::exception_ptr failure;
  std::mutex failure_mutex;
  auto worker = [&] {
    try {
      for (;;) {
        if (stopped()) return;
        const std::int64_t i = take();
        if (i >= n) return;
        std::optional<io::RunRecord> record = engine.run(todo[static_cast<std::size_t>(i)], settings.stop);
        release_free_memory();
        if (!record) return;
        std::lock_guard<std::mutex> lock(store_mutex);
        io::RunStore::append(store, {*record});
        ++outcome.completed;
      }
    } catch (const std::exception& e) {
      if (size_ > 1) {
        // Stop the whole job now, not after the other ranks have run everything left: the
        // finished runs are in the rank stores, and --resume computes the rest.
        std::lock_guard<std::mutex> lock(mpi_mutex());
        std::cerr << "touchstone: error (MPI rank " << rank_ << "): " << e.what() << "\n";
        MPI_Abort(MPI_COMM_WORLD, 1);
      }
      std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure) failure = std::current_exception();
    } catch (...) {
      std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failure) failure = std::current_exception();
    }
  };
  const int workers = std::max(1, threads);
  tbb::parallel_for(tbb::blocked_range<int>(0, workers, 1),
                    [&](const tbb::blocked_range<int>& r) {
                      for (int w = r.begin(); w != r.end(); ++w) worker();
                    },
                    tbb::simple_partitioner());
  if (rank_ != 0) {
    std::lock_guard<std::mutex> lock(mpi_mutex());
    std::int64_t none = 0;
    MPI_Send(&none, 1, MPI_INT64_T, 0, kDone, MPI_COMM_WORLD);
  }
  if (dispatcher.joinable()) dispatcher.join();
  if (failure) std::rethrow_exception(failure);
  outcome.interrupted = stopped();
  return outcome;
}

#else

bool mpi_built() { return false; }

MpiSession::MpiSession() {
  throw Error("this build has no MPI mode (CMake did not find MPI, or TS_MPI is off)", {}, "--mpi");
}
MpiSession::~MpiSession() = default;
void MpiSession::barrier() {}
void MpiSession::abort(int code) { std::exit(code); }
bool MpiSession::same_on_every_rank(std::uint64_t) { return true; }
DriveOutcome MpiSession::drive(RunEngine&, const std::vector<RunTask>&, const std::filesystem::path&, int,
                               const DriveSettings&) {
  return {};
}

#endif

}  // namespace ts::experiments
