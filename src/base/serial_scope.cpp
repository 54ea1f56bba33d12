// strata — see serial_scope.hpp.
#include "base/serial_scope.hpp"

namespace strata::detail {
namespace {
thread_local bool serial = false;
}  // namespace

bool serial_passes() noexcept { return serial; }

SerialScope::SerialScope(bool on) noexcept : previous_(serial) { serial = on; }
SerialScope::~SerialScope() { serial = previous_; }

}  // namespace strata::detail
