// strata — how much host memory the process may still take.
//
// Why: Linux grants large allocations without backing them (overcommit) and pins
// page-locked buffers without regard to what else the process will touch, so a plan that
// asks for more than the machine has is not refused at the allocation: the process is
// killed later by the kernel's out-of-memory killer, with no message. Plans that size
// large host buffers (the GPU backend's pinned staging and spilled contribution blocks,
// next to the host factor) check their total against this figure first and throw
// strata::OutOfMemory naming the bytes instead.
#pragma once
#include <cstddef>

namespace strata {

/// Bytes of host memory available to this process now: the kernel's MemAvailable
/// (/proc/meminfo; free memory plus what it can reclaim without swapping), lowered to
/// the room left under the process's cgroup (v2) memory.max when one is set. 0 when
/// neither can be read (not Linux): callers then apply no host limit.
std::size_t available_host_memory();

}  // namespace strata
