// Arithmetic that both C++ kernels (contact_kernel.cc, neighbor_kernel.cc) need in their hot
// loops, as the hardware rounds it, without calls into the C library.
#pragma once
#include <cmath>
#include <limits>

namespace drumheat {

// nearbyint(v) in the default rounding mode (to nearest, ties to even), without the call into
// libm that the baseline x86-64 build makes of it (no rounding instruction before SSE4.1): the
// call, once per candidate pair or particle along a periodic axis, made the compiler keep the
// loop's values on the stack around it. For |v| < 2^52 (2^23 in float), adding and subtracting
// 2^52 rounds to an integer as the hardware rounds, and copysign keeps the sign of a zero;
// larger values are integers already (and a NaN stays one).
template <typename S>
inline S round_to_even(S v) {
  const S big = S(1) / std::numeric_limits<S>::epsilon();
  const S a = std::fabs(v);
  return a < big ? std::copysign((a + big) - big, v) : v;
}

}  // namespace drumheat
