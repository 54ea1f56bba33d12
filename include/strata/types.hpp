// strata — basic index and scalar types shared by every public header.
#pragma once

#include <cstdint>

namespace strata {

/// Index type for rows, columns, offsets and counts everywhere in strata (0-based).
/// 64 bits so that nnz(L) of large 3D problems never overflows.
using index_t = std::int64_t;

}  // namespace strata
