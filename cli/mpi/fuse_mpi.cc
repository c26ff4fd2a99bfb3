// scalefuse fuse ... --mpi: the cluster plan run by MPI ranks (docs/cluster.md). Rank 0 plans, then
// for each stage (integrate, regularize, ..., sort) hands out tiles one at a time to the ranks
// that ask (so fast ranks take more), starts the next stage once every tile has finished this one,
// and merges at the end. With one rank, it runs the tiles itself.
// Built only when CMake finds MPI (SCALEFUSE_HAVE_MPI).
#include <mpi.h>

#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "engine/error.h"
#include "scheduler/cluster.h"
#include "scheduler/cluster_stage.h"

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

  // 2. Stages: for each stage in turn, rank 0 hands out the tiles one at a time; each other rank
  // asks for work, runs it, reports, asks again. A rank that asks while the stage's last tiles
  // are still running waits for the next stage (the barrier every stage needs).
  const std::vector<std::string>& stages = tile_stages();
  std::vector<Outcome> failures;  // "tile K failed on rank R: why", with the tile's outcome code
  const auto failed = [&](int stage, int tile, int rank, const Outcome& o) {
    failures.push_back({o.code, "tile " + std::to_string(tile) + " failed on rank " + std::to_string(rank) +
                                    " in stage " + stages[std::size_t(stage)] + ": " + o.message});
    std::fprintf(stderr, "mpi: %s\n", failures.back().message.c_str());
  };
  if (mpi.size == 1) {
    for (std::size_t s = 0; s < stages.size() && failures.empty(); ++s)
      for (std::size_t k = 0; k < n && failures.empty(); ++k) {
        const Outcome o = attempt([&] { run_tile(job, long(k), tile_args, stages[s]); });
        if (o.code != 0) failed(int(s), int(k), 0, o);
      }
  } else if (mpi.rank == 0) {
    std::size_t stage = 0, next = 0, running = 0;
    std::vector<int> waiting;  // ranks that asked while the stage ends elsewhere
    int active = mpi.size - 1;
    while (active > 0) {
      int report[3];  // stage, tile (-1: none yet), outcome code
      MPI_Status st;
      MPI_Recv(report, 3, MPI_INT, MPI_ANY_SOURCE, kTagReport, MPI_COMM_WORLD, &st);
      const int from = st.MPI_SOURCE;
      if (report[1] >= 0) {
        --running;
        if (report[2] != 0) {
          int len = 0;
          MPI_Recv(&len, 1, MPI_INT, from, kTagMessage, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
          Outcome o{report[2], std::string(std::size_t(len), '\0')};
          if (len > 0) MPI_Recv(o.message.data(), len, MPI_CHAR, from, kTagMessage, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
          failed(report[0], report[1], from, o);
        }
      }
      waiting.push_back(from);
      // The stage is over when its last tile has reported: the next one starts.
      if (failures.empty() && next == n && running == 0 && stage + 1 < stages.size()) {
        ++stage;
        next = 0;
        if (!a.quiet) std::fprintf(stderr, "mpi: stage %s\n", stages[stage].c_str());
      }
      // After a failure no new tile starts: the merge cannot run, and the others' work is kept
      // (checkpointed) for a rerun. Ranks leave when no work can come.
      const bool over = !failures.empty() || (stage + 1 == stages.size() && next == n);
      while (!waiting.empty() && (over || next < n)) {
        const int rank = waiting.back();
        waiting.pop_back();
        int work[2] = {int(stage), -1};
        if (!over) {
          work[1] = int(next++);
          ++running;
        }
        MPI_Send(work, 2, MPI_INT, rank, kTagTile, MPI_COMM_WORLD);
        if (work[1] < 0) --active;
        else if (!a.quiet && stage == 0) std::fprintf(stderr, "mpi: rank %d runs tile %d of %zu\n", rank, work[1], n);
      }
    }
  } else {
    int report[3] = {0, -1, 0};
    Outcome last;
    for (;;) {
      MPI_Send(report, 3, MPI_INT, 0, kTagReport, MPI_COMM_WORLD);
      if (report[1] >= 0 && report[2] != 0) {
        const int len = int(last.message.size());
        MPI_Send(&len, 1, MPI_INT, 0, kTagMessage, MPI_COMM_WORLD);
        if (len > 0) MPI_Send(last.message.data(), len, MPI_CHAR, 0, kTagMessage, MPI_COMM_WORLD);
      }
      int work[2] = {0, -1};
      MPI_Recv(work, 2, MPI_INT, 0, kTagTile, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      if (work[1] < 0) break;
      last = attempt([&] { run_tile(job, work[1], tile_args, stages[std::size_t(work[0])]); });
      report[0] = work[0];
      report[1] = work[1];
      report[2] = last.code;
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
