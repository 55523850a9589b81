// `mpirun -np N vmap build`: the V-map construction shared over N processes with MPI, each on
// its own GPU or its share of the CPU cores, the links gathered into one .vmap byte for byte
// that of a single-process build (or left as shards: src/mpi/shard_file.h).
//
// How the work is cut and put back together: src/mpi/top_pairs.h (no MPI) and src/mpi/share.h.
// Rank 0 reads the input (on the host's cores, while MPI starts) and sends the points to the
// others; every rank builds the same octree from them. Ranks whose input options (Options::
// input_key) or build parameters differ stop the job.
// Schedules: "dynamic" (the default: rank 0 hands out chunks of jobs to whichever rank asks; a
// thread of rank 0 answers while rank 0 builds too; each rank resolves its chunks over one
// octree) or "static" (each rank its share of the jobs by a work estimate, fixed in advance). A
// failure on one rank (bad input, out of memory, a write error) ends every rank with that rank's
// message; nothing is written unless every rank got that far, and the output appears whole
// (io::AtomicFile) or not at all.
//
// A vmap built without MPI (VMAP_HAVE_MPI unset) has launched() false: mpirun then starts N
// independent single-process builds, as before.
#pragma once

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "vmap/vmap.h"

namespace vmap::mpi {

// Built with MPI, and this process was started by mpirun (Open MPI's environment).
bool launched();

struct Options {
    std::string output;        // .vmap (or the index, with shards)
    bool shards = false;       // one file of links per rank and an index (shard_file.h)
    bool count_links = false;  // count, write nothing (BuildParams::keep_links false)
    std::string schedule =
        "dynamic";             // dynamic | static (docs/scaling.md: dynamic balanced better)
    int threads = 0;           // CPU threads per rank; 0: the host's cores / the ranks on the host
    int chunks_per_rank = 16;  // dynamic: chunks of jobs handed out, per rank (top_pairs.h)
    // What names the input (its path and the options that change the points read): only rank
    // 0 reads it, so every rank's must be rank 0's.
    std::string input_key;
};

struct Result {
    bool root = true;   // rank 0: vm, stats and summary are its, and it printed nothing yet
    VisibilityMap vm;   // the points and octree; the links unless shards or count_links
    BuildStats stats;   // summed over the ranks (times: the slowest rank's)
    double save_seconds = 0;
    std::vector<std::string> summary;  // lines about the ranks, for the build summary
    // Rank 0: the slowest rank's seconds in each phase, in order: start (the process's start
    // to MPI_Init done), input and octree (on a thread during start), probe (the rest of them
    // after MPI_Init, and the input check), job list, construction, settle, exchange (links to
    // the owners of their ends), gather (to rank 0), save.
    std::vector<std::pair<std::string, double>> phases;
};

// Rank 0's reading of the input: the points, with the build parameters completed (the
// octree's). Run on a thread while MPI starts: its failure ends the job like any other.
using ReadInput = std::function<PointSet(BuildParams&)>;

// The shared build: every rank calls it; rank 0 reads the input and shares it. Rank 0 throws
// vmap::Error with the failing rank's message (the job's exit status is rank 0's); the others
// return normally, so that mpirun does not end rank 0 before it has printed.
Result build(const ReadInput& read, BuildParams params, const Options& opt,
             const std::string& source);

}  // namespace vmap::mpi
