// strata — the unit roundoff of double precision, for bounds on rounding errors.
#pragma once

#include <limits>

namespace strata {

/// u = 2⁻⁵³, half the distance from 1 to the next double: |fl(x ∘ y) − x ∘ y| ≤ u |x ∘ y|
/// for the basic operations (Higham, Accuracy and Stability of Numerical Algorithms, §2.2).
inline constexpr double kUnitRoundoff = 0.5 * std::numeric_limits<double>::epsilon();

}  // namespace strata
