// Backends that evaluate leaf-pair visibility in bulk (paper §4.3: the leaf visibility status
// table, LVS). The V-map builder hands a backend batches of node-pair rectangles of the
// leaf-by-leaf matrix and reads back bit-packed answers; link extraction stays on the host.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "util/progress.h"
#include "vmap/octree.h"
#include "vmap/options.h"
#include "vmap/visibility.h"

namespace vmap::detail {

struct NodePairContext;  // visibility/node_pair.h

// One rectangle: leaves [row0, row0 + rows) (under node a) by [col0, col0 + cols) (under
// node b, after a in preorder, so every leaf pair in it has row < col). Bit (r, c) is at word
// word_offset + r * row_words(cols) + c / 32, bit c % 32 (rows padded to whole 32-bit words).
struct PairJob {
    int32_t a = 0, b = 0;
    int32_t row0 = 0, rows = 0, col0 = 0, cols = 0;
    uint64_t word_offset = 0;
};

inline uint64_t row_words(int32_t cols) { return (static_cast<uint64_t>(cols) + 31) / 32; }
inline uint64_t job_words(const PairJob& j) { return j.rows * row_words(j.cols); }

// A node pair of the construction's frontier, a before b in preorder.
struct NodePairRef {
    int32_t a = 0, b = 0;
};

class Backend {
  public:
    virtual ~Backend() = default;
    virtual std::string name() const = 0;  // "cpu (16 threads)", "cuda (NVIDIA H100 ...)"
    // Called once per build, before any batch.
    virtual void prepare(const Octree& tree, const VisibilityParams& vp,
                         uint64_t max_batch_words) = 0;
    // Starts evaluating a batch into buffer `slot` (0 or 1); may return before it is done, so
    // the host can extract links from the other slot meanwhile (paper §6.2: asynchronous).
    virtual void submit(std::span<const PairJob> jobs, uint64_t words, int slot) = 0;
    // Waits for the batch in `slot`, adds its work to `wc`, returns its bits (host memory, valid
    // until the next submit to that slot).
    virtual const uint32_t* wait(int slot, WorkCounters& wc) = 0;
    // Seconds the backend spent evaluating (GPU: kernel time from events; CPU: wall time of
    // the evaluation), summed over the batches waited for.
    virtual double busy_seconds() const = 0;
    // Peak device memory the backend held, bytes (0 for the CPU).
    virtual uint64_t peak_device_bytes() const { return 0; }
    // Node bounds of the build (construction "nodes"), valid until the last wait; a backend may
    // use them to restrict each job's walk to its shaft (same answers). Called after prepare.
    virtual void set_node_context(const NodePairContext*) {}
    // Decides node pairs with decide_node_pair (node_pair.h) under the context given to
    // set_node_context: out[i] is the PairDecision of pairs[i], as a byte (undecided for a pair
    // not worth_deciding); adds the tree nodes
    // tested to *shaft_node_tests. False (nothing written) when the backend leaves the
    // decisions to the host (the CPU); the answers are the host's, bit for bit.
    virtual bool decide(std::span<const NodePairRef> /*pairs*/, uint8_t* /*out*/,
                        uint64_t* /*shaft_node_tests*/) {
        return false;
    }
    // Another backend on the same device for a lane of the construction (vmap/frontier.h): its
    // own streams and buffers, the tree and node context of this one (after prepare and
    // set_node_context), its kernel time and device memory counted with this one's. nullptr
    // where lanes do not pay (the CPU: one frontier already keeps every core busy).
    virtual std::unique_ptr<Backend> lane() { return nullptr; }
    // Whether the backend itself adds evaluated leaf pairs to the progress while a batch runs.
    virtual bool counts_progress() const { return false; }
    // Leaf pairs per second to expect, for the estimate reported before the work starts (0:
    // no idea).
    virtual double expected_pairs_per_second() const { return 0; }
    // Counts evaluated leaf pairs into `p` while a batch runs (and stops early once it is
    // cancelled); null for none.
    void set_progress(Progress* p) { progress_ = p; }

  protected:
    Progress* progress_ = nullptr;
};

std::unique_ptr<Backend> make_cpu_backend();
// nullptr with *why set when CUDA is not built in or no device is present. `device` indexes the
// devices CUDA_VISIBLE_DEVICES leaves visible (-1: 0); one past them throws vmap::Error.
std::unique_ptr<Backend> make_cuda_backend(std::string* why, int device = 0);
// CUDA devices visible to this process (0 without CUDA or without a device).
int cuda_device_count();

// The backend for `requested`: cpu; cuda (vmap::Error without a usable device); auto (the GPU
// when usable, else the CPU with the reason in *note). The rule is util/device.h's. `device`:
// the CUDA device index (-1: 0); one past those visible is vmap::Error.
std::unique_ptr<Backend> make_backend(vmap::Backend requested, std::string* note,
                                      int device = -1);

}  // namespace vmap::detail
