// scalefuse fuse ... --mpi: the cluster plan run by MPI ranks (docs/cluster.md). Rank 0 plans, then
// hands out tiles one at a time to the ranks that ask (so fast ranks take more), collects their
// outcomes, and merges once every tile is integrated. With one rank, it runs the tiles itself.
// Built only when CMake finds MPI (SCALEFUSE_HAVE_MPI).
#include <mpi.h>

#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "engine/error.h"
#include "scheduler/cluster.h"

namespace sf::cli {

namespace {

constexpr int kTagReport = 1, kTagMessage = 2, kTagTile = 3;

// Outcome codes, as the process's exit codes: 0 ok, 1 internal error, 2 bad input.
struct Outcome {
  int code = 0;
  std::string message;
};

template <typename F>
Outcome attempt(F&& f) {
  try {
    f();
    return {};
  } catch (const InputError& e) {
    return {2, e.what()};
  } catch (const std::exception& e) {
    return {1, e.what()};
  }
}

void broadcast(Outcome& o) {
  MPI_Bcast(&o.code, 1, MPI_INT, 0, MPI_COMM_WORLD);
  int n = int(o.message.size());
  MPI_Bcast(&n, 1, MPI_INT, 0, MPI_COMM_WORLD);
  o.message.resize(std::size_t(n));
  if (n > 0) MPI_Bcast(o.message.data(), n, MPI_CHAR, 0, MPI_COMM_WORLD);
}

[[noreturn]] void fail(const Outcome& o) {
  if (o.code == 2) throw InputError(o.message);
  throw std::runtime_error(o.message);
}

class MpiSession {
 public:
  MpiSession() {
    int provided = 0;
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
  }
  ~MpiSession() { MPI_Finalize(); }
  int rank = 0, size = 1;
};

}  // namespace

void run_fuse_mpi(const FuseArgs& a, std::size_t tiles) {
  MpiSession mpi;
  if (tiles == 0) tiles = 4 * std::size_t(mpi.size > 1 ? mpi.size - 1 : 1);  // small tiles balance the ranks
  const std::string job = a.job.empty() ? a.output + ".job" : a.job;
  FuseArgs tile_args;  // the job options each tile runs with
  tile_args.threads = a.threads;
  tile_args.memory_limit = a.memory_limit;
  tile_args.checkpoint_every = a.checkpoint_every;
  tile_args.checkpoint_seconds = a.checkpoint_seconds;
  tile_args.quiet = a.quiet;

  // 1. Rank 0 plans (or finds the plan of an earlier run); every rank learns the outcome.
  Outcome planned;
  if (mpi.rank == 0) {
    FuseArgs pa = a;
    pa.job = job;
    planned = attempt([&] { run_plan(pa, tiles); });
  }
  broadcast(planned);
  if (planned.code != 0) {
    if (mpi.rank == 0) fail(planned);
    return;  // rank 0 reports it
  }
  const std::size_t n = read_cluster_plan(job).tiles.size();

  // 2. Tiles: rank 0 hands them out; each other rank asks for one, runs it, reports, asks again.
  std::vector<Outcome> failures;  // "tile K failed on rank R: why", with the tile's outcome code
  if (mpi.size == 1) {
    for (std::size_t k = 0; k < n && failures.empty(); ++k) {
      const Outcome o = attempt([&] { run_tile(job, long(k), tile_args); });
      if (o.code != 0) failures.push_back({o.code, "tile " + std::to_string(k) + " failed on rank 0: " + o.message});
    }
  } else if (mpi.rank == 0) {
    std::size_t next = 0;
    int active = mpi.size - 1;
    while (active > 0) {
      int report[2];  // tile (-1: none yet), outcome code
      MPI_Status st;
      MPI_Recv(report, 2, MPI_INT, MPI_ANY_SOURCE, kTagReport, MPI_COMM_WORLD, &st);
      const int from = st.MPI_SOURCE;
      if (report[0] >= 0 && report[1] != 0) {
        int len = 0;
        MPI_Recv(&len, 1, MPI_INT, from, kTagMessage, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        std::string message(std::size_t(len), '\0');
        if (len > 0) MPI_Recv(message.data(), len, MPI_CHAR, from, kTagMessage, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        failures.push_back({report[1], "tile " + std::to_string(report[0]) + " failed on rank " + std::to_string(from) +
                                           ": " + message});
        std::fprintf(stderr, "mpi: %s\n", failures.back().message.c_str());
      }
      // After a failure no new tile starts: the merge cannot run, and the others' work is kept
      // (their tiles are checkpointed) for a rerun.
      int tile = -1;
      if (failures.empty() && next < n) tile = int(next++);
      MPI_Send(&tile, 1, MPI_INT, from, kTagTile, MPI_COMM_WORLD);
      if (tile < 0) --active;
      else if (!a.quiet) std::fprintf(stderr, "mpi: rank %d runs tile %d of %zu\n", from, tile, n);
    }
  } else {
    int report[2] = {-1, 0};
    Outcome last;
    for (;;) {
      MPI_Send(report, 2, MPI_INT, 0, kTagReport, MPI_COMM_WORLD);
      if (report[0] >= 0 && report[1] != 0) {
        const int len = int(last.message.size());
        MPI_Send(&len, 1, MPI_INT, 0, kTagMessage, MPI_COMM_WORLD);
        if (len > 0) MPI_Send(last.message.data(), len, MPI_CHAR, 0, kTagMessage, MPI_COMM_WORLD);
      }
      int tile = -1;
      MPI_Recv(&tile, 1, MPI_INT, 0, kTagTile, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      if (tile < 0) break;
      last = attempt([&] { run_tile(job, tile, tile_args); });
      report[0] = tile;
      report[1] = last.code;
    }
  }

  // 3. Rank 0 merges when every tile is integrated; the others finalize (and wait there).
  Outcome tiles_done;
  if (mpi.rank == 0 && !failures.empty()) {
    // Bad input (2) only if every failure was bad input; else an internal error (1).
    tiles_done.code = 2;
    for (const Outcome& f : failures) {
      if (f.code != 2) tiles_done.code = 1;
      tiles_done.message += (tiles_done.message.empty() ? "" : "; ") + f.message;
    }
  }
  broadcast(tiles_done);
  if (mpi.rank != 0) return;
  if (tiles_done.code != 0) fail(tiles_done);
  FuseArgs merge_args = tile_args;
  merge_args.stats_json = a.stats_json;
  run_merge(job, a.output, merge_args);
}

}  // namespace sf::cli
