// strata — JSON forms of the statistics structs that the command line (`--json`) and the
// benchmark drivers write, in one place so that the files agree field for field. Header
// only, for programs that already use nlohmann-json; the library itself does not.
// nlohmann-json finds these by argument-dependent lookup: `json j = stats.devices;`.
#pragma once

#include <nlohmann/json.hpp>

#include "strata/distributed.hpp"
#include "strata/stats.hpp"

namespace strata {

/// GPU seconds per phase of a factorization (FactorStats::device_phases).
inline void to_json(nlohmann::json& j, const FactorStats::DevicePhases& d) {
  j = {{"assembly", d.assembly},
       {"small_fronts", d.small_fronts},
       {"large_fronts", d.large_fronts},
       {"store", d.store},
       {"tiled_fronts", d.tiled_fronts},
       {"host", d.host},
       {"setup", d.setup},
       {"tiled_assembly", d.tiled_assembly},
       {"tiled_slabs", d.tiled_slabs},
       {"tiled_pivot_columns", d.tiled_pivot_columns},
       {"tiled_cb_update", d.tiled_cb_update},
       {"tiled_store", d.tiled_store}};
}

/// One part a worker ran (DeviceStats::parts).
inline void to_json(nlohmann::json& j, const PartRun& r) {
  const char* kind = r.kind == PartRun::Kind::subtree ? "subtree"
                     : r.kind == PartRun::Kind::upper ? "upper"
                                                      : "top";
  j = {{"kind", kind},
       {"index", r.index},
       {"stolen", r.stolen},
       {"start_seconds", r.start_seconds},
       {"end_seconds", r.end_seconds},
       {"flops", r.flops}};
}

/// One worker (GPU) of a multi-worker factorization (FactorStats::devices).
inline void to_json(nlohmann::json& j, const DeviceStats& d) {
  j = {{"worker", d.worker},
       {"device", d.device},
       {"busy_seconds", d.busy_seconds},
       {"idle_seconds", d.idle_seconds},
       {"subtrees_run", d.subtrees_run},
       {"subtrees_stolen", d.subtrees_stolen},
       {"upper_parts_run", d.upper_parts_run},
       {"bytes_transferred", d.bytes_transferred},
       {"flops", d.flops},
       {"fronts_split", d.fronts_split},
       {"fronts_distributed", d.fronts_distributed},
       {"strips_helped", d.strips_helped},
       {"parts", d.parts}};
}

/// One MPI rank of a distributed run (DistributedStats::per_rank).
inline void to_json(nlohmann::json& j, const RankStats& r) {
  j = {{"rank", r.rank},
       {"workers", r.workers},
       {"subtrees", r.subtrees},
       {"factor_flops", r.factor_flops},
       {"factor_seconds", r.factor_seconds},
       {"factor_bytes_sent", r.factor_bytes_sent},
       {"factor_bytes_received", r.factor_bytes_received},
       {"values_bytes", r.values_bytes},
       {"factor_bytes_held", r.factor_bytes_held},
       {"solve_seconds", r.solve_seconds},
       {"solve_bytes_sent", r.solve_bytes_sent},
       {"solve_bytes_received", r.solve_bytes_received}};
}

}  // namespace strata
