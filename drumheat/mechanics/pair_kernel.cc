// DEM pair kernel for CPU as one loop: an XLA FFI custom call (drumheat/mechanics/cpu_kernel.py).
//
// The same contact law as drumheat.mechanics.contact_forces.contact_law (linear spring-dashpot
// normal force clipped at zero, Cundall-Strack tangential spring rotated onto the tangent plane,
// Coulomb cap, tangential dashpot only while sticking; Weigler digest [2.1]-[2.4],
// peers/liggghts/README.md "hooke" with tangential history) for 3D spheres of one material in
// float32, with an optional periodic z axis. Inputs: positions, velocities, spins (N, 3),
// radii, masses (N), pairs idx (2, M) with padding N, springs (M, 3). Outputs: contact forces
// and torques per particle (N, 3), new springs (M, 3), overlap, centre distance and normal force
// per pair (M) (zero where the pair does not touch), and the largest overlap / smaller radius
// (1). The pair loop runs on several threads for large M (DRUMHEAT_KERNEL_THREADS caps them); the
// force sums then depend on the thread count (round-off), not on anything else.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>
#include "xla/ffi/api/ffi.h"
namespace ffi = xla::ffi;

static ffi::Error PairForcesImpl(
    ffi::Buffer<ffi::F32> pos, ffi::Buffer<ffi::F32> vel, ffi::Buffer<ffi::F32> omg,
    ffi::Buffer<ffi::F32> rad, ffi::Buffer<ffi::F32> mass, ffi::Buffer<ffi::S32> idx,
    ffi::Buffer<ffi::F32> spring, float kn, float kt, float zn, float zt, float mu, float dt,
    float L, ffi::ResultBuffer<ffi::F32> force, ffi::ResultBuffer<ffi::F32> torque,
    ffi::ResultBuffer<ffi::F32> nspring, ffi::ResultBuffer<ffi::F32> ovl_out,
    ffi::ResultBuffer<ffi::F32> dist_out, ffi::ResultBuffer<ffi::F32> fn_out,
    ffi::ResultBuffer<ffi::F32> max_ratio) {
  const int64_t n = rad.dimensions()[0];
  const int64_t m = spring.dimensions()[0];
  const float *x = pos.typed_data(), *v = vel.typed_data(), *w = omg.typed_data();
  const float *r = rad.typed_data(), *ms = mass.typed_data(), *sp = spring.typed_data();
  const int32_t *I = idx.typed_data(), *J = idx.typed_data() + m;
  float* S = nspring->typed_data();
  float *OV = ovl_out->typed_data(), *DI = dist_out->typed_data(), *FN = fn_out->typed_data();
  const float sqkn = std::sqrt(kn), sqkt = std::sqrt(kt);
  // pairs [k0, k1) into the force / torque accumulators F, T (N, 3); returns the largest
  // overlap / smaller radius seen. Per-pair outputs are disjoint between ranges.
  auto pair_range = [&](int64_t k0, int64_t k1, float* F, float* T) -> float {
  float max_ov = 0.f;
  for (int64_t k = k0; k < k1; ++k) {
    const int32_t i = I[k], j = J[k];
    float* s = S + 3 * k;
    OV[k] = 0.f; DI[k] = 0.f; FN[k] = 0.f; s[0] = s[1] = s[2] = 0.f;
    if (i >= n) continue;
    float d0 = x[3*j] - x[3*i], d1 = x[3*j+1] - x[3*i+1], d2 = x[3*j+2] - x[3*i+2];
    if (L > 0) d2 -= L * std::nearbyint(d2 / L);
    const float dist2 = d0*d0 + d1*d1 + d2*d2;
    const float rs = r[i] + r[j];
    if (dist2 >= rs * rs) continue;
    const float dist = std::sqrt(dist2);
    const float ov = rs - dist;
    const float inv = dist > 0 ? 1.f / dist : 0.f;
    const float n0 = d0*inv, n1 = d1*inv, n2 = d2*inv;
    const float li = r[i] - 0.5f*ov, lj = -(r[j] - 0.5f*ov);
    const float ai0 = li*n0, ai1 = li*n1, ai2 = li*n2, aj0 = lj*n0, aj1 = lj*n1, aj2 = lj*n2;
    const float* wi = w + 3*i; const float* wj = w + 3*j;
    // v_rel = (v_j + w_j x a_j) - (v_i + w_i x a_i)
    const float vr0 = v[3*j]   + (wj[1]*aj2 - wj[2]*aj1) - v[3*i]   - (wi[1]*ai2 - wi[2]*ai1);
    const float vr1 = v[3*j+1] + (wj[2]*aj0 - wj[0]*aj2) - v[3*i+1] - (wi[2]*ai0 - wi[0]*ai2);
    const float vr2 = v[3*j+2] + (wj[0]*aj1 - wj[1]*aj0) - v[3*i+2] - (wi[0]*ai1 - wi[1]*ai0);
    const float me = ms[i]*ms[j]/(ms[i]+ms[j]);
    const float sqm = std::sqrt(me);
    const float vn = vr0*n0 + vr1*n1 + vr2*n2;
    float fn = kn*ov - 2.f*zn*sqkn*sqm*vn; if (fn < 0.f) fn = 0.f;
    const float vt0 = vr0 - vn*n0, vt1 = vr1 - vn*n1, vt2 = vr2 - vn*n2;
    const float* so = sp + 3*k;
    const float xin = so[0]*n0 + so[1]*n1 + so[2]*n2;
    float xp0 = so[0] - xin*n0, xp1 = so[1] - xin*n1, xp2 = so[2] - xin*n2;
    const float lo = std::sqrt(so[0]*so[0] + so[1]*so[1] + so[2]*so[2]);
    const float lp = std::sqrt(xp0*xp0 + xp1*xp1 + xp2*xp2);
    const float sc = lp > 0 ? lo / lp : 1.f;
    float x0 = xp0*sc + vt0*dt, x1 = xp1*sc + vt1*dt, x2 = xp2*sc + vt2*dt;
    float fs0 = -kt*x0, fs1 = -kt*x1, fs2 = -kt*x2;
    const float fl = std::sqrt(fs0*fs0 + fs1*fs1 + fs2*fs2);
    const float fc = mu*fn;
    float ft0, ft1, ft2;
    if (fl > fc) {
      const float ratio = fc / fl;
      ft0 = fs0*ratio; ft1 = fs1*ratio; ft2 = fs2*ratio;
      x0 = -ft0/kt; x1 = -ft1/kt; x2 = -ft2/kt;
    } else {
      const float gt = 2.f*zt*sqkt*sqm;
      ft0 = fs0 - gt*vt0; ft1 = fs1 - gt*vt1; ft2 = fs2 - gt*vt2;
    }
    s[0] = x0; s[1] = x1; s[2] = x2;
    const float f0 = fn*n0 + ft0, f1 = fn*n1 + ft1, f2 = fn*n2 + ft2;  // on j
    F[3*j] += f0; F[3*j+1] += f1; F[3*j+2] += f2;
    F[3*i] -= f0; F[3*i+1] -= f1; F[3*i+2] -= f2;
    // torque_i = a_i x (-f), torque_j = a_j x f
    T[3*i]   -= ai1*f2 - ai2*f1; T[3*i+1] -= ai2*f0 - ai0*f2; T[3*i+2] -= ai0*f1 - ai1*f0;
    T[3*j]   += aj1*f2 - aj2*f1; T[3*j+1] += aj2*f0 - aj0*f2; T[3*j+2] += aj0*f1 - aj1*f0;
    OV[k] = ov; DI[k] = dist; FN[k] = fn;
    const float ratio_ov = ov / (r[i] < r[j] ? r[i] : r[j]);
    if (ratio_ov > max_ov) max_ov = ratio_ov;
  }
  return max_ov;
  };
  float* F0 = force->typed_data();
  float* T0 = torque->typed_data();
  std::memset(F0, 0, sizeof(float) * 3 * n);
  std::memset(T0, 0, sizeof(float) * 3 * n);
  // threads: DRUMHEAT_KERNEL_THREADS or the hardware's, one per 100 000 pair slots at most
  // (below that, starting threads every step next to XLA's own pool costs more than it saves:
  // measured 2x slower at N = 2 000 with 8 000 slots per thread)
  int64_t nt = std::thread::hardware_concurrency();
  if (const char* e = std::getenv("DRUMHEAT_KERNEL_THREADS")) nt = std::atoi(e);
  if (nt > m / 100000) nt = m / 100000;
  if (nt < 1) nt = 1;
  if (nt == 1) {
    max_ratio->typed_data()[0] = pair_range(0, m, F0, T0);
    return ffi::Error::Success();
  }
  // thread t accumulates into its own buffers (thread 0 into the outputs), summed afterwards
  std::vector<std::vector<float>> acc(nt - 1, std::vector<float>(6 * n, 0.f));
  std::vector<float> mx(nt, 0.f);
  std::vector<std::thread> pool;
  for (int64_t t = 1; t < nt; ++t)
    pool.emplace_back([&, t] {
      mx[t] = pair_range(m * t / nt, m * (t + 1) / nt, acc[t - 1].data(),
                         acc[t - 1].data() + 3 * n);
    });
  mx[0] = pair_range(0, m / nt, F0, T0);
  for (auto& th : pool) th.join();
  float max_ov = mx[0];
  for (int64_t t = 1; t < nt; ++t) {
    const float* a = acc[t - 1].data();
    for (int64_t q = 0; q < 3 * n; ++q) { F0[q] += a[q]; T0[q] += a[3 * n + q]; }
    if (mx[t] > max_ov) max_ov = mx[t];
  }
  max_ratio->typed_data()[0] = max_ov;
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    PairForces, PairForcesImpl,
    ffi::Ffi::Bind()
        .Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>()
        .Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::S32>>()
        .Arg<ffi::Buffer<ffi::F32>>()
        .Attr<float>("kn").Attr<float>("kt").Attr<float>("zn").Attr<float>("zt")
        .Attr<float>("mu").Attr<float>("dt").Attr<float>("L")
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>()
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>()
        .Ret<ffi::Buffer<ffi::F32>>());
