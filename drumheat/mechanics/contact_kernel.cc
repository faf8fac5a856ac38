// DEM contact kernel for CPU as one loop: an XLA FFI custom call (mechanics/cpu_kernel.py).
//
// The same contact law as drumheat.mechanics.contact_forces.contact_law (linear spring-dashpot
// normal force clipped at zero, Cundall-Strack tangential spring rotated onto the tangent plane,
// Coulomb cap, tangential dashpot only while sticking; Weigler digest [2.1]-[2.4],
// peers/liggghts/README.md "hooke" with tangential history) for 3D spheres of one material in
// float32, with an optional periodic z axis, for the particle-particle pairs and the
// particle-wall contacts (the wall geometry is evaluated in JAX and comes in as distance, unit
// normal and wall velocity per particle and wall).
//
// The new pair and wall springs may share their buffers with the old ones (cpu_kernel.py aliases
// them): each slot reads its old spring before it writes the new one, and nothing else.
//
// Inputs: positions, velocities, spins (N, 3); radii, masses (N); pairs (2, M) with padding N;
// pair springs (M, 3); per particle and wall: distance (N, W), normal from the wall to the
// particle (N, W, 3), wall velocity at the particle (N, W, 3), wall springs (N, W, 3); wall
// contact parameters (5, W): kn, kt, zeta_n, zeta_t, mu. Outputs: contact forces and torques
// per particle (N, 3); new pair springs (M, 3); overlap, centre distance and normal force per
// pair (M); new wall springs (N, W, 3); overlap and normal force per wall slot (N, W) (all zero
// where nothing touches); the largest overlap / radius (smaller radius of a pair) (1).
//
// Contact conduction (optional, attribute law >= 0; drumheat/mechanics/conduction.py): with
// temperatures T (N, float64) in, the heat flow into each particle Q (N, float64) out,
// q = g (T_j - T_i) through every touching pair, g = h pi min(r_i, r_j)^2 (law 0, "projected":
// Weigler digest eq. [2.7] with A_p = pi d^2 / 4 of the smaller sphere) or g = h sqrt(A_c) with
// A_c the area of the overlap circle (law 1, "overlap": LIGGGHTS heat/gran/conduction). With
// law < 0, T and Q have length 0.
//
// Threads: the pair slots and wall slots are cut into C equal chunks, C = the threads of XLA's
// intra-op pool, at most one chunk per MIN_CHUNK pair slots (DRUMHEAT_KERNEL_THREADS sets C).
// The calling thread runs chunk 0 and then takes any chunk no pool thread has started; chunk c
// accumulates its forces in its own buffer and the buffers are summed in chunk order, so the
// result depends on C (round-off) and on nothing else, whichever thread ran which chunk.
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>
#include "xla/ffi/api/ffi.h"
namespace ffi = xla::ffi;

namespace {

constexpr int64_t MIN_CHUNK = 8000;  // pair slots per chunk at least (below: one thread)
constexpr double kPi = 3.14159265358979323846;

struct Law {
  float kn, kt, zn, zt, mu, sqkn, sqkt;
};

// One contact between partner A and partner B: unit normal n from A to B, overlap ov, relative
// velocity vr of B's contact point against A's, effective mass me, old spring so. Writes the
// new spring to s (which may be so: the springs are updated in place) and returns the normal
// force; f receives the force on B.
inline float contact(const Law& c, float dt, const float n[3], float ov, const float vr[3],
                     float me, const float* so, float* s, float f[3]) {
  const float sqm = std::sqrt(me);
  const float vn = vr[0]*n[0] + vr[1]*n[1] + vr[2]*n[2];
  float fn = c.kn*ov - 2.f*c.zn*c.sqkn*sqm*vn;
  if (fn < 0.f) fn = 0.f;
  const float vt0 = vr[0] - vn*n[0], vt1 = vr[1] - vn*n[1], vt2 = vr[2] - vn*n[2];
  const float xin = so[0]*n[0] + so[1]*n[1] + so[2]*n[2];
  const float xp0 = so[0] - xin*n[0], xp1 = so[1] - xin*n[1], xp2 = so[2] - xin*n[2];
  const float lo = std::sqrt(so[0]*so[0] + so[1]*so[1] + so[2]*so[2]);
  const float lp = std::sqrt(xp0*xp0 + xp1*xp1 + xp2*xp2);
  const float sc = lp > 0 ? lo / lp : 1.f;
  float x0 = xp0*sc + vt0*dt, x1 = xp1*sc + vt1*dt, x2 = xp2*sc + vt2*dt;
  const float fs0 = -c.kt*x0, fs1 = -c.kt*x1, fs2 = -c.kt*x2;
  const float fl = std::sqrt(fs0*fs0 + fs1*fs1 + fs2*fs2);
  const float fc = c.mu*fn;
  float ft0, ft1, ft2;
  if (fl > fc) {
    const float ratio = fc / fl;
    ft0 = fs0*ratio; ft1 = fs1*ratio; ft2 = fs2*ratio;
    x0 = -ft0/c.kt; x1 = -ft1/c.kt; x2 = -ft2/c.kt;
  } else {
    const float gt = 2.f*c.zt*c.sqkt*sqm;
    ft0 = fs0 - gt*vt0; ft1 = fs1 - gt*vt1; ft2 = fs2 - gt*vt2;
  }
  s[0] = x0; s[1] = x1; s[2] = x2;  // so is not read after this
  f[0] = fn*n[0] + ft0; f[1] = fn*n[1] + ft1; f[2] = fn*n[2] + ft2;
  return fn;
}

// w x a
inline void cross(const float* w, const float* a, float* out) {
  out[0] = w[1]*a[2] - w[2]*a[1];
  out[1] = w[2]*a[0] - w[0]*a[2];
  out[2] = w[0]*a[1] - w[1]*a[0];
}

// Per-chunk accumulators (6 N floats of force and torque, then N doubles of heat) that live
// across calls (no allocation and page faults every step).
using Buffer = std::vector<double>;
std::mutex g_buf_mu;
std::vector<std::unique_ptr<Buffer>> g_bufs;

std::unique_ptr<Buffer> take_buffer(size_t size) {
  std::unique_ptr<Buffer> b;
  {
    std::lock_guard<std::mutex> lock(g_buf_mu);
    if (!g_bufs.empty()) { b = std::move(g_bufs.back()); g_bufs.pop_back(); }
  }
  if (!b) b = std::make_unique<Buffer>();
  if (b->size() < size) b->resize(size);
  return b;
}

void give_buffer(std::unique_ptr<Buffer> b) {
  std::lock_guard<std::mutex> lock(g_buf_mu);
  g_bufs.push_back(std::move(b));
}

// conductance of a touching pair (see the header), W/K
inline double conductance(int law, double h, double ri, double rj, double L) {
  if (law == 0) {
    const double rm = ri < rj ? ri : rj;
    return h * kPi * rm * rm;
  }
  const double area = -0.25 * kPi * (L - ri - rj) * (L + ri - rj) * (L - ri + rj) *
                      (L + ri + rj) / (L * L);
  return area > 0 ? h * std::sqrt(area) : 0.0;
}

// Chunks 1..C-1 offered to the pool; see the header for the protocol's purpose. A pool task
// registers in `active` before it looks at `closed`, and the caller sets `closed` before it
// waits for `active` to drop to zero, so no task touches the caller's frame after it returns.
struct Job {
  std::atomic<int> next{1};
  std::atomic<int> active{0};
  std::atomic<bool> closed{false};
  int nchunks = 1;
  std::function<void(int)> run;
};

void help(const std::shared_ptr<Job>& job) {
  job->active.fetch_add(1);
  if (!job->closed.load()) {
    for (int c = job->next.fetch_add(1); c < job->nchunks; c = job->next.fetch_add(1))
      job->run(c);
  }
  job->active.fetch_sub(1);
}

}  // namespace

static ffi::Error ContactsImpl(
    ffi::ThreadPool pool, ffi::Buffer<ffi::F32> pos, ffi::Buffer<ffi::F32> vel,
    ffi::Buffer<ffi::F32> omg, ffi::Buffer<ffi::F32> rad, ffi::Buffer<ffi::F32> mass,
    ffi::Buffer<ffi::S32> pairs, ffi::Buffer<ffi::F32> spring, ffi::Buffer<ffi::F32> wdist,
    ffi::Buffer<ffi::F32> wnrm, ffi::Buffer<ffi::F32> wvel, ffi::Buffer<ffi::F32> wspring,
    ffi::Buffer<ffi::F32> wparams, ffi::Buffer<ffi::F64> temp, float kn, float kt, float zn,
    float zt, float mu, float dt, float L, int32_t law, double h,
    ffi::ResultBuffer<ffi::F32> force, ffi::ResultBuffer<ffi::F32> torque,
    ffi::ResultBuffer<ffi::F32> nspring, ffi::ResultBuffer<ffi::F32> ovl_out,
    ffi::ResultBuffer<ffi::F32> dist_out, ffi::ResultBuffer<ffi::F32> fn_out,
    ffi::ResultBuffer<ffi::F32> nwspring, ffi::ResultBuffer<ffi::F32> wovl_out,
    ffi::ResultBuffer<ffi::F32> wfn_out, ffi::ResultBuffer<ffi::F32> max_ratio,
    ffi::ResultBuffer<ffi::F64> heat) {
  const int64_t n = rad.dimensions()[0];
  const int64_t m = spring.dimensions()[0];
  const int64_t nw = wdist.dimensions().size() > 1 ? wdist.dimensions()[1] : 0;
  const float *x = pos.typed_data(), *v = vel.typed_data(), *w = omg.typed_data();
  const float *r = rad.typed_data(), *ms = mass.typed_data(), *sp = spring.typed_data();
  const int32_t* P = pairs.typed_data();
  const float *WD = wdist.typed_data(), *WN = wnrm.typed_data(), *WV = wvel.typed_data();
  const float *WS = wspring.typed_data(), *WP = wparams.typed_data();
  float *S = nspring->typed_data(), *WSo = nwspring->typed_data();
  float *OV = ovl_out->typed_data(), *DI = dist_out->typed_data(), *FN = fn_out->typed_data();
  float *WO = wovl_out->typed_data(), *WF = wfn_out->typed_data();
  const double* TK = temp.typed_data();
  const bool heat_on = law >= 0;
  const Law pp{kn, kt, zn, zt, mu, std::sqrt(kn), std::sqrt(kt)};
  std::vector<Law> pw(nw);
  for (int64_t q = 0; q < nw; ++q) {
    const float k = WP[q], t = WP[nw + q];
    pw[q] = Law{k, t, WP[2*nw + q], WP[3*nw + q], WP[4*nw + q], std::sqrt(k), std::sqrt(t)};
  }

  // pair slots [k0, k1) and wall slots [s0, s1) into the accumulators F, T (N, 3); returns
  // the largest overlap ratio seen. Per-slot outputs are disjoint between chunks.
  auto work = [&](int64_t k0, int64_t k1, int64_t s0, int64_t s1, float* F, float* T,
                  double* Q) -> float {
    float max_ov = 0.f;
    for (int64_t k = k0; k < k1; ++k) {
      const int32_t i = P[k], j = P[m + k];
      float* s = S + 3*k;
      OV[k] = 0.f; DI[k] = 0.f; FN[k] = 0.f;
      if (i >= n) { s[0] = s[1] = s[2] = 0.f; continue; }
      float d0 = x[3*j] - x[3*i], d1 = x[3*j+1] - x[3*i+1], d2 = x[3*j+2] - x[3*i+2];
      // nearest periodic image (positions are kept in [0, L), so |d2| < L); same as
      // d2 - L rint(d2 / L), without a libm call per slot
      if (L > 0) d2 = d2 > 0.5f*L ? d2 - L : (d2 < -0.5f*L ? d2 + L : d2);
      const float dist2 = d0*d0 + d1*d1 + d2*d2;
      const float rs = r[i] + r[j];
      if (dist2 >= rs * rs) { s[0] = s[1] = s[2] = 0.f; continue; }
      const float dist = std::sqrt(dist2);
      const float ov = rs - dist;
      const float inv = dist > 0 ? 1.f / dist : 0.f;
      const float nr[3] = {d0*inv, d1*inv, d2*inv};
      const float li = r[i] - 0.5f*ov, lj = -(r[j] - 0.5f*ov);
      const float ai[3] = {li*nr[0], li*nr[1], li*nr[2]};
      const float aj[3] = {lj*nr[0], lj*nr[1], lj*nr[2]};
      float ci[3], cj[3];
      cross(w + 3*i, ai, ci);
      cross(w + 3*j, aj, cj);
      const float vr[3] = {v[3*j] + cj[0] - v[3*i] - ci[0], v[3*j+1] + cj[1] - v[3*i+1] - ci[1],
                           v[3*j+2] + cj[2] - v[3*i+2] - ci[2]};
      float f[3];
      FN[k] = contact(pp, dt, nr, ov, vr, ms[i]*ms[j]/(ms[i]+ms[j]), sp + 3*k, s, f);
      F[3*j] += f[0]; F[3*j+1] += f[1]; F[3*j+2] += f[2];
      F[3*i] -= f[0]; F[3*i+1] -= f[1]; F[3*i+2] -= f[2];
      // torque_i = a_i x (-f), torque_j = a_j x f
      T[3*i]   -= ai[1]*f[2] - ai[2]*f[1]; T[3*i+1] -= ai[2]*f[0] - ai[0]*f[2];
      T[3*i+2] -= ai[0]*f[1] - ai[1]*f[0];
      T[3*j]   += aj[1]*f[2] - aj[2]*f[1]; T[3*j+1] += aj[2]*f[0] - aj[0]*f[2];
      T[3*j+2] += aj[0]*f[1] - aj[1]*f[0];
      OV[k] = ov; DI[k] = dist;
      if (heat_on) {
        const double q = conductance(law, h, r[i], r[j], dist) * (TK[j] - TK[i]);
        Q[i] += q; Q[j] -= q;
      }
      const float ratio_ov = ov / (r[i] < r[j] ? r[i] : r[j]);
      if (ratio_ov > max_ov) max_ov = ratio_ov;
    }
    // walls: partner A is the wall (no spin, infinite mass), B the particle
    for (int64_t q = s0; q < s1; ++q) {
      const int64_t p = q / nw, wl = q % nw;
      float* s = WSo + 3*q;
      const float ov = r[p] - WD[q];
      WO[q] = 0.f; WF[q] = 0.f;
      if (!(ov > 0.f)) { s[0] = s[1] = s[2] = 0.f; continue; }
      const float* nr = WN + 3*q;
      const float l = -(r[p] - 0.5f*ov);
      const float a[3] = {l*nr[0], l*nr[1], l*nr[2]};
      float c[3];
      cross(w + 3*p, a, c);
      const float vr[3] = {v[3*p] + c[0] - WV[3*q], v[3*p+1] + c[1] - WV[3*q+1],
                           v[3*p+2] + c[2] - WV[3*q+2]};
      float f[3];
      WF[q] = contact(pw[wl], dt, nr, ov, vr, ms[p], WS + 3*q, s, f);
      F[3*p] += f[0]; F[3*p+1] += f[1]; F[3*p+2] += f[2];
      T[3*p]   += a[1]*f[2] - a[2]*f[1]; T[3*p+1] += a[2]*f[0] - a[0]*f[2];
      T[3*p+2] += a[0]*f[1] - a[1]*f[0];
      WO[q] = ov;
      if (ov / r[p] > max_ov) max_ov = ov / r[p];
    }
    return max_ov;
  };

  float* F0 = force->typed_data();
  float* T0 = torque->typed_data();
  double* Q0 = heat->typed_data();
  std::memset(F0, 0, sizeof(float) * 3 * n);
  std::memset(T0, 0, sizeof(float) * 3 * n);
  if (heat_on) std::memset(Q0, 0, sizeof(double) * n);
  const int64_t slots = n * nw;
  int64_t nc = pool.num_threads();
  if (nc > m / MIN_CHUNK) nc = m / MIN_CHUNK;
  if (const char* e = std::getenv("DRUMHEAT_KERNEL_THREADS")) nc = std::atoi(e);  // exactly
  if (nc > m) nc = m;
  if (nc < 1) nc = 1;
  if (nc == 1) {
    max_ratio->typed_data()[0] = work(0, m, 0, slots, F0, T0, Q0);
    return ffi::Error::Success();
  }
  // a buffer holds 6 N floats (forces, torques) in its first 3 N doubles, then N doubles
  std::vector<std::unique_ptr<Buffer>> acc(nc - 1);
  for (auto& b : acc) b = take_buffer(4 * n);
  std::vector<float> mx(nc, 0.f);
  auto job = std::make_shared<Job>();
  job->nchunks = static_cast<int>(nc);
  job->run = [&](int c) {
    float *F = F0, *T = T0;
    double* Q = Q0;
    if (c > 0) {
      double* b = acc[c - 1]->data();
      F = reinterpret_cast<float*>(b); T = F + 3 * n; Q = b + 3 * n;
      std::memset(b, 0, sizeof(double) * (heat_on ? 4 : 3) * n);
    }
    mx[c] = work(m * c / nc, m * (c + 1) / nc, slots * c / nc, slots * (c + 1) / nc, F, T, Q);
  };
  for (int64_t t = 1; t < nc; ++t) pool.Schedule([job] { help(job); });
  job->run(0);
  for (int c = job->next.fetch_add(1); c < job->nchunks; c = job->next.fetch_add(1)) job->run(c);
  job->closed.store(true);
  while (job->active.load() != 0) std::this_thread::yield();
  float max_ov = mx[0];
  for (int64_t c = 1; c < nc; ++c) {
    const double* b = acc[c - 1]->data();
    const float* a = reinterpret_cast<const float*>(b);
    for (int64_t q = 0; q < 3 * n; ++q) { F0[q] += a[q]; T0[q] += a[3 * n + q]; }
    if (heat_on)
      for (int64_t q = 0; q < n; ++q) Q0[q] += b[3 * n + q];
    if (mx[c] > max_ov) max_ov = mx[c];
  }
  for (auto& b : acc) give_buffer(std::move(b));
  max_ratio->typed_data()[0] = max_ov;
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    Contacts, ContactsImpl,
    ffi::Ffi::Bind()
        .Ctx<ffi::ThreadPool>()
        .Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>()
        .Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::S32>>()
        .Arg<ffi::Buffer<ffi::F32>>()
        .Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>()
        .Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F32>>().Arg<ffi::Buffer<ffi::F64>>()
        .Attr<float>("kn").Attr<float>("kt").Attr<float>("zn").Attr<float>("zt")
        .Attr<float>("mu").Attr<float>("dt").Attr<float>("L")
        .Attr<int32_t>("law").Attr<double>("h")
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>()
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>()
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>()
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F64>>());
