// strata — an internal cap on the device memory the CUDA executor's buffers allocate.
//
// Failure injection for tests (not an environment variable, not a public option): with a
// cap set, every DeviceBuffer allocation is charged against it before cudaMalloc is
// called, and the first one that would go over it throws OutOfMemory naming its bytes, as
// a real cudaMalloc failure does. Charges accumulate (frees give nothing back), so
// set_device_allocation_cap(0) makes the next device allocation fail and a cap of B lets
// B bytes of allocations through. Compiled into every build (the CUDA-less build never
// charges anything), so tests reach it without CUDA headers.
#pragma once

#include <cstddef>

namespace strata::numeric {

/// Caps the bytes of device allocations from now on (resets the running total).
void set_device_allocation_cap(std::size_t bytes);
/// Removes the cap (the default).
void clear_device_allocation_cap();
/// Bytes charged since the cap was last set or cleared (counted also without a cap).
std::size_t device_bytes_charged();
/// Called before every device allocation: throws OutOfMemory(bytes, what) when the cap is
/// set and `bytes` would go over it; otherwise adds `bytes` to the running total.
void charge_device_allocation(std::size_t bytes, const char* what);

}  // namespace strata::numeric
