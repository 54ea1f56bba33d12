// strata bench tools — a timeline of a program's GPU work, for machines without Nsight
// Systems (the lent GPU machines have ncu but no nsys: .library/device/KINDS.md).
//
// What: a shared library loaded into any CUDA program with LD_PRELOAD. From its start it
// records, through NVIDIA's CUPTI activity API, every kernel (device, stream, start, end,
// grid and block size, name), memory copy (kind, bytes, device and stream; peer copies
// with their source and destination device) and memset, and at the program's exit writes
// them to the CSV file named by the environment variable STRATA_CUPTI_TRACE, one activity
// a line, ordered by start:
//
//   kind,device,stream,start_ns,end_ns,bytes,detail
//
// kind is kernel, memcpy, memcpy_p2p, memset, or api: a CUDA runtime call on the host (its
// "device" column is -1 and its "stream" column the calling thread's id, shortened to 32
// bits); start_ns and end_ns are CUPTI's timestamps (nanoseconds, one clock for the host
// and all devices); bytes is 0 for kernels and calls; detail is the kernel's name with its
// grid and block ("name grid=gx.gy.gz block=bx.by.bz"), a copy's direction (HtoD, DtoH,
// DtoD, PtoP src->dst, ...), the call's name, or empty. bench/tools/trace_summary.py cuts
// the devices' timeline into windows of activity and sums each window by device, kernel
// name and copy kind, and lists the host's long calls in it.
//
// Why: where a factorization's time goes between kernels (copies, gaps, launch chains) is
// what per-kernel profilers do not show.
//
// Source: the CUPTI activity API (NVIDIA, "CUPTI User's Guide", "Activity API"):
// cuptiActivityRegisterCallbacks, cuptiActivityEnable, cuptiActivityFlushAll. Records are
// copied out of CUPTI's buffers as they complete, so a buffer is reused at once.
//
// The host's runtime calls are recorded only with STRATA_CUPTI_API=1: recording them costs
// time in every call, enough to open gaps of its own between launches of a few tens of
// microseconds (bench/history.md), so the device's timeline is then not the untraced one.
//
// Without STRATA_CUPTI_TRACE set the library does nothing. Errors from CUPTI are reported
// on stderr once, and the program runs on untraced. Child processes inherit LD_PRELOAD
// (a benchmark's popen of git or nvidia-smi): a process that recorded nothing writes
// nothing, a forked copy of the traced process writes nothing, and "%p" in the file name stands for
// the process id, for programs that start several CUDA processes (MPI ranks).
#include <cupti.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>
#include <vector>

namespace {

struct Activity {
  const char* kind;
  std::uint32_t device, stream;
  std::uint64_t start, end, bytes;
  std::string detail;
};

std::mutex g_mutex;
std::vector<Activity> g_records;
std::atomic<bool> g_enabled{false};
pid_t g_pid = 0;  // the process that enabled the recording (a fork's copy writes nothing)
constexpr std::size_t kBufferBytes = 8u << 20;

void report(const char* what, CUptiResult r) {
  const char* msg = nullptr;
  cuptiGetResultString(r, &msg);
  std::fprintf(stderr, "cupti_trace: %s failed: %s (no trace)\n", what, msg ? msg : "?");
}

const char* copy_kind(std::uint8_t k) {
  switch (k) {
    case CUPTI_ACTIVITY_MEMCPY_KIND_HTOD:
      return "HtoD";
    case CUPTI_ACTIVITY_MEMCPY_KIND_DTOH:
      return "DtoH";
    case CUPTI_ACTIVITY_MEMCPY_KIND_DTOD:
      return "DtoD";
    case CUPTI_ACTIVITY_MEMCPY_KIND_HTOH:
      return "HtoH";
    case CUPTI_ACTIVITY_MEMCPY_KIND_PTOP:
      return "PtoP";
    default:
      return "other";
  }
}

void CUPTIAPI buffer_requested(std::uint8_t** buffer, std::size_t* size, std::size_t* max_records) {
  *size = kBufferBytes;
  *buffer = static_cast<std::uint8_t*>(std::aligned_alloc(8, kBufferBytes));
  *max_records = 0;
}

void CUPTIAPI buffer_completed(CUcontext, std::uint32_t, std::uint8_t* buffer, std::size_t,
                               std::size_t valid) {
  std::vector<Activity> got;
  CUpti_Activity* rec = nullptr;
  while (cuptiActivityGetNextRecord(buffer, valid, &rec) == CUPTI_SUCCESS) {
    switch (rec->kind) {
      case CUPTI_ACTIVITY_KIND_KERNEL:
      case CUPTI_ACTIVITY_KIND_CONCURRENT_KERNEL: {
        const auto* k = reinterpret_cast<const CUpti_ActivityKernel10*>(rec);
        char shape[96];
        std::snprintf(shape, sizeof shape, " grid=%d.%d.%d block=%d.%d.%d", k->gridX, k->gridY,
                      k->gridZ, k->blockX, k->blockY, k->blockZ);
        got.push_back({"kernel", k->deviceId, k->streamId, k->start, k->end, 0,
                       std::string(k->name ? k->name : "?") + shape});
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMCPY: {
        const auto* m = reinterpret_cast<const CUpti_ActivityMemcpy6*>(rec);
        got.push_back({"memcpy", m->deviceId, m->streamId, m->start, m->end, m->bytes,
                       copy_kind(m->copyKind)});
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMCPY2: {
        const auto* m = reinterpret_cast<const CUpti_ActivityMemcpyPtoP4*>(rec);
        got.push_back({"memcpy_p2p", m->deviceId, m->streamId, m->start, m->end, m->bytes,
                       std::string(copy_kind(m->copyKind)) + " " + std::to_string(m->srcDeviceId) +
                           "->" + std::to_string(m->dstDeviceId)});
        break;
      }
      case CUPTI_ACTIVITY_KIND_RUNTIME: {
        const auto* a = reinterpret_cast<const CUpti_ActivityAPI*>(rec);
        const char* name = nullptr;
        if (cuptiGetCallbackName(CUPTI_CB_DOMAIN_RUNTIME_API, a->cbid, &name) != CUPTI_SUCCESS)
          name = nullptr;
        got.push_back({"api", static_cast<std::uint32_t>(-1), a->threadId, a->start, a->end, 0,
                       name ? name : "?"});
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMSET: {
        const auto* m = reinterpret_cast<const CUpti_ActivityMemset4*>(rec);
        got.push_back({"memset", m->deviceId, m->streamId, m->start, m->end, m->bytes, ""});
        break;
      }
      default:
        break;
    }
  }
  std::free(buffer);
  const std::lock_guard<std::mutex> lock(g_mutex);
  for (Activity& a : got) g_records.push_back(std::move(a));
}

// The CSV's detail field: commas and quotes out of the way.
std::string csv_field(const std::string& s) {
  std::string o = "\"";
  for (char c : s) o += c == '"' ? '\'' : c;
  return o + "\"";
}

struct Tracer {
  Tracer() {
    const char* path = std::getenv("STRATA_CUPTI_TRACE");
    if (!path || !*path) return;
    CUptiResult r = cuptiActivityRegisterCallbacks(buffer_requested, buffer_completed);
    if (r != CUPTI_SUCCESS) {
      report("cuptiActivityRegisterCallbacks", r);
      return;
    }
    const char* api = std::getenv("STRATA_CUPTI_API");
    const bool calls = api && std::string(api) == "1";
    for (CUpti_ActivityKind k :
         {CUPTI_ACTIVITY_KIND_CONCURRENT_KERNEL, CUPTI_ACTIVITY_KIND_MEMCPY,
          CUPTI_ACTIVITY_KIND_MEMCPY2, CUPTI_ACTIVITY_KIND_MEMSET, CUPTI_ACTIVITY_KIND_RUNTIME}) {
      if (k == CUPTI_ACTIVITY_KIND_RUNTIME && !calls) continue;
      if ((r = cuptiActivityEnable(k)) != CUPTI_SUCCESS) {
        report("cuptiActivityEnable", r);
        return;
      }
    }
    g_pid = getpid();
    g_enabled = true;
  }
  ~Tracer() {
    if (!g_enabled || getpid() != g_pid) return;
    cuptiActivityFlushAll(1);
    const std::lock_guard<std::mutex> lock(g_mutex);
    if (g_records.empty()) return;
    std::string path = std::getenv("STRATA_CUPTI_TRACE");
    if (const auto at = path.find("%p"); at != std::string::npos)
      path.replace(at, 2, std::to_string(getpid()));
    std::FILE* f = std::fopen(path.c_str(), "w");
    if (!f) {
      std::fprintf(stderr, "cupti_trace: cannot write %s\n", path.c_str());
      return;
    }
    std::sort(g_records.begin(), g_records.end(),
              [](const Activity& a, const Activity& b) { return a.start < b.start; });
    std::fprintf(f, "kind,device,stream,start_ns,end_ns,bytes,detail\n");
    for (const Activity& a : g_records)
      std::fprintf(f, "%s,%d,%u,%llu,%llu,%llu,%s\n", a.kind, static_cast<int>(a.device), a.stream,
                   static_cast<unsigned long long>(a.start), static_cast<unsigned long long>(a.end),
                   static_cast<unsigned long long>(a.bytes), csv_field(a.detail).c_str());
    std::fclose(f);
    std::fprintf(stderr, "cupti_trace: %zu activities written to %s\n", g_records.size(),
                 path.c_str());
  }
};

// Constructed when the library is loaded, destroyed at the program's exit. CUPTI hands
// over a context's records when the context is destroyed, so records of contexts the
// program tore down are in by then; the flush takes the rest.
Tracer g_tracer;

}  // namespace
