"""Experiment: the DEM pair kernel as one C++ loop (an XLA custom call) against drumheat's JAX
kernel on CPU. Not used by the package; it measures what the design option would gain.

docs/performance.md explains why the JAX force kernel stays at about a third of LIGGGHTS' speed
per core on XLA:CPU: some twenty passes over the pair slots plus a scatter-add. This script
compiles the same contact law (linear spring-dashpot, Cundall-Strack tangential history with
Coulomb cap, as :func:`drumheat.mechanics.contact_forces.contact_law`; 3D, one material,
float32, optional periodic z) as a single C++ loop with ``g++ -O3``, registers it with
``jax.ffi``, and times both on the same state of the 3D drum slice:

* XLA: ``DEM._forces`` of a DEM without walls (gravity + pairs), jitted with ``JIT_OPTIONS``,
  on a state advanced 200 steps in the rotating drum;
* C++: the custom call (forces, torques, new springs, overlaps and normal forces), plus gravity.

It also checks that both give the same springs and forces to float32 round-off (a contact at
the stick/slip threshold may flip and differ by more). Needs ``g++`` and jaxlib's FFI headers
(``jax.ffi.include_dir()``).

Usage::

    python scripts/bench_cpu_pair_kernel.py [--n 2000 10000 50000]
        [--data-dir /tmp/drumheat_vs_liggghts/restart]   # states of bench_vs_liggghts.py
"""

from __future__ import annotations

import argparse
import ctypes
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import drumheat  # noqa: F401  (x64 for the host side)
from drumheat.geometry import DrumShell
from drumheat.mechanics import contact_params, make_dem, make_particles
from drumheat.mechanics.integrator import JIT_OPTIONS

CPP = r"""
#include <cmath>
#include <cstdint>
#include <cstring>
#include "xla/ffi/api/ffi.h"
namespace ffi = xla::ffi;

static ffi::Error PairForcesImpl(
    ffi::Buffer<ffi::F32> pos, ffi::Buffer<ffi::F32> vel, ffi::Buffer<ffi::F32> omg,
    ffi::Buffer<ffi::F32> rad, ffi::Buffer<ffi::F32> mass, ffi::Buffer<ffi::S32> idx,
    ffi::Buffer<ffi::F32> spring, float kn, float kt, float zn, float zt, float mu, float dt,
    float L, ffi::ResultBuffer<ffi::F32> force, ffi::ResultBuffer<ffi::F32> torque,
    ffi::ResultBuffer<ffi::F32> nspring, ffi::ResultBuffer<ffi::F32> ovl_out,
    ffi::ResultBuffer<ffi::F32> fn_out) {
  const int64_t n = rad.dimensions()[0];
  const int64_t m = spring.dimensions()[0];
  const float *x = pos.typed_data(), *v = vel.typed_data(), *w = omg.typed_data();
  const float *r = rad.typed_data(), *ms = mass.typed_data(), *sp = spring.typed_data();
  const int32_t *I = idx.typed_data(), *J = idx.typed_data() + m;
  float *F = force->typed_data(), *T = torque->typed_data(), *S = nspring->typed_data();
  float *OV = ovl_out->typed_data(), *FN = fn_out->typed_data();
  std::memset(F, 0, sizeof(float) * 3 * n);
  std::memset(T, 0, sizeof(float) * 3 * n);
  const float sqkn = std::sqrt(kn), sqkt = std::sqrt(kt);
  for (int64_t k = 0; k < m; ++k) {
    const int32_t i = I[k], j = J[k];
    float* s = S + 3 * k;
    OV[k] = 0.f; FN[k] = 0.f; s[0] = s[1] = s[2] = 0.f;
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
    OV[k] = ov; FN[k] = fn;
  }
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
        .Ret<ffi::Buffer<ffi::F32>>().Ret<ffi::Buffer<ffi::F32>>());
"""


def build_kernel() -> str:
    """Compile the C++ kernel into a temporary folder and register it; return the target."""
    d = Path(tempfile.mkdtemp(prefix="drumheat_ffi_"))
    (d / "pair.cc").write_text(CPP)
    subprocess.run(["g++", "-O3", "-march=native", "-shared", "-fPIC", "-std=c++17", "-w",
                    f"-I{jax.ffi.include_dir()}", str(d / "pair.cc"), "-o", str(d / "pair.so")],
                   check=True)
    lib = ctypes.cdll.LoadLibrary(str(d / "pair.so"))
    jax.ffi.register_ffi_target("drumheat_pair_forces", jax.ffi.pycapsule(lib.PairForces),
                                platform="cpu")
    return "drumheat_pair_forces"


def state_of(n, data_dir):
    """A settled rotating-drum state: the LIGGGHTS data file if present, else a lattice bed
    (scripts/bench_dem.py) run for 3000 steps."""
    sys.path.insert(0, str(Path(__file__).parent))
    f = Path(data_dir) / f"drum_N{n}.data" if data_dir else None
    if f is not None and f.exists():
        import bench_vs_liggghts as B

        pos, vel, omega, radius, L = B.read_data(str(f))
        return pos, vel, omega, np.asarray(radius), L, f"LIGGGHTS state {f.name}"
    import bench_dem

    dem, st = bench_dem.build(3, n, False, jnp.float32)
    st = dem.run(st, 3000, chunk=3000)
    return (np.asarray(st.position), np.asarray(st.velocity), np.asarray(st.angular_velocity),
            np.asarray(dem.particles.radius), dem.neighbor.periodic_length,
            "lattice bed after 3000 steps")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2000, 10000])
    ap.add_argument("--data-dir", default="/tmp/drumheat_vs_liggghts/restart")
    ap.add_argument("--repeat", type=int, default=50)
    a = ap.parse_args(argv)
    target = build_kernel()
    print(f"{os.cpu_count()} CPU cores, load {os.getloadavg()[0]:.1f}, JAX {jax.__version__}\n")
    print("| N | state | pair slots | touching | XLA kernel (ms) | C++ loop (ms) | XLA / C++ | "
          "max spring difference / max spring |")
    print("|---|---|---|---|---|---|---|---|")
    for n in a.n:
        pos, vel, omega, radius, L, what = state_of(n, a.data_dir)
        part = make_particles(radius, 2500.0)
        params = contact_params(1.001e5, restitution=0.5, restitution_model="linear",
                                friction=0.5, wall_friction=0.5)
        kw = dict(dim=3, periodic_length=L, dt=1e-5, skin=0.004, dtype=jnp.float32)
        drum = make_dem(part, [DrumShell(0.125, rpm=9.55)], params, **kw)
        st = drum.init(pos, velocity=vel, angular_velocity=omega)
        st = drum.run_steps(st, 200)  # tangential springs built up, bed still in the drum
        # the timed XLA kernel: the same particles and pairs without the wall (pairs only)
        dem = make_dem(part, [], params, bounds=(drum.domain_lo, drum.domain_hi), **kw)
        st = st._replace(wall_spring=jnp.zeros((n, 0, 3), jnp.float32))
        m_slots = st.nbrs.idx.shape[1]
        f32 = np.float32
        c = lambda t: f32(np.asarray(t)[0, 0])  # noqa: E731
        mass = dem.particles.mass.astype(jnp.float32)
        rad = dem.particles.radius.astype(jnp.float32)
        g = jnp.asarray(dem.gravity, jnp.float32)

        def cpp(pos, vel, w, idx, spring):
            outs = [jax.ShapeDtypeStruct((n, 3), jnp.float32)] * 2 + [
                jax.ShapeDtypeStruct((m_slots, 3), jnp.float32),
                jax.ShapeDtypeStruct((m_slots,), jnp.float32),
                jax.ShapeDtypeStruct((m_slots,), jnp.float32)]
            f, t, s, _, _ = jax.ffi.ffi_call(target, outs)(
                pos, vel, w, rad, mass, idx.astype(jnp.int32), spring,
                kn=c(params.kn_pp), kt=c(params.kt_pp), zn=c(params.zeta_n_pp),
                zt=c(params.zeta_t_pp), mu=c(params.mu_pp), dt=f32(dem.dt), L=f32(L))
            return f + mass[:, None] * g, t, s

        def xla(pos, vel, w, idx, spring):
            import dataclasses

            nb = dataclasses.replace(st.nbrs, idx=idx)
            return dem._forces(pos, vel, w, st.time, nb, spring, st.wall_spring)[:3]

        args = (st.position, st.velocity, st.angular_velocity, st.nbrs.idx, st.pair_spring)
        f_cpp = jax.jit(cpp, compiler_options=JIT_OPTIONS)
        ra, rb = f_cpp(*args), xla(*args)
        dspring = float(jnp.max(jnp.abs(ra[2] - rb[2])) / jnp.max(jnp.abs(rb[2])))
        touching = int(jnp.sum(dem.contacts(st).pair_mask))

        def timed(f):
            jax.block_until_ready(f(*args))
            t0 = time.perf_counter()
            for _ in range(a.repeat):
                r = f(*args)
            jax.block_until_ready(r)
            return (time.perf_counter() - t0) / a.repeat * 1e3

        tx = min(timed(xla) for _ in range(3))
        tc = min(timed(f_cpp) for _ in range(3))
        print(f"| {n} | {what} | {m_slots} | {touching} | {tx:.2f} | {tc:.2f} | {tx / tc:.1f} | "
              f"{dspring:.1e} |", flush=True)


if __name__ == "__main__":
    main()
