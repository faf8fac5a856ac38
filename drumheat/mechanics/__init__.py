"""drumheat.mechanics: soft-sphere DEM on cell-list neighbour lists (jax-md's layout).

Contact laws (:mod:`.contact_forces`), the contact forces of a step behind one signature, in
JAX or the C++ loop (:mod:`.forces`), neighbour lists with tangential history
(:mod:`.neighbors`), velocity-Verlet integration with a checked chunked runner
(:mod:`.integrator`), per-step contact conduction in the force loop (:mod:`.conduction`), the
opt-in C++ contact kernel for CPUs (:mod:`.cpu_kernel`), bed generation (:mod:`.pour`),
analysis (:mod:`.analysis`), what the float type resolves (:mod:`.precision`) and the
exceptions (:mod:`.errors`).
"""

from drumheat.mechanics.contact_forces import (  # noqa: F401
    ContactParams,
    contact_params,
    critical_time_step,
    damping_ratio_from_restitution,
    normal_stiffness_from_youngs,
    restitution_from_damping_ratio,
)
from drumheat.mechanics.conduction import PairConduction  # noqa: F401
from drumheat.mechanics.errors import (  # noqa: F401
    DEMError,
    NeighborListError,
    NonFiniteError,
    OverlapError,
    ParticleEscapeError,
)
from drumheat.mechanics.forces import Contacts, ContactForces, make_contact_forces  # noqa: F401
from drumheat.mechanics.integrator import (  # noqa: F401
    DEM,
    CountingUpdate,
    DEMAccuracyWarning,
    DEMState,
    Particles,
    make_dem,
    make_particles,
)
