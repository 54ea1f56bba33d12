// strata — umbrella header of the C++ API.
#pragma once

#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"
#include "strata/options.hpp"
#include "strata/solver.hpp"
#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"
#include "strata/types.hpp"
