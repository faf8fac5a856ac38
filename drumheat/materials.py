"""Material and gas property library.

Solid properties come from the reference digests (``../shared/reference/``); each entry names
its source. A scene refers to a material by name and may override any property inline
(``[[groups]] density = ...``).

Only what the heat and contact models need is stored: density, specific heat capacity,
thermal conductivity, Young's modulus, Poisson ratio and emissivity.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace


@dataclass(frozen=True)
class Material:
    """Properties of a particle (or wall) material, SI units.

    Attributes
    ----------
    name : str
    density : float
        kg/m3.
    heat_capacity : float
        Specific heat capacity, J/(kg K).
    conductivity : float
        Thermal conductivity, W/(m K).
    youngs_modulus : float
        Pa.
    poisson_ratio : float
        Dimensionless.
    emissivity : float
        Grey-body emissivity, dimensionless.
    source : str
        Where the numbers come from.
    """

    name: str
    density: float
    heat_capacity: float
    conductivity: float
    youngs_modulus: float
    poisson_ratio: float
    emissivity: float
    source: str = ""


#: Property names a scene may override inline.
PROPERTY_NAMES = tuple(f.name for f in fields(Material) if f.name not in ("name", "source"))

MATERIALS: dict[str, Material] = {
    m.name: m
    for m in [
        # weigler-thermal-dem.md, Table 2-1 and Table 3-1 (lambda). Poisson ratio and emissivity
        # are not in the thesis: typical values for aluminium (0.33; 0.1 for a lacquer-free
        # surface, but the spheres are lacquered, so 0.9 would apply to the coated spheres;
        # radiation is negligible at these temperatures, digest section 4).
        Material("aluminium", 2700.0, 900.0, 237.0, 7.0e10, 0.33, 0.9,
                 "weigler-thermal-dem.md Table 2-1, 3-1; nu, eps typical"),
        # weigler-thermal-dem.md, Table 2-1 / Table 5-1. E = 1.95e11 Pa is the thesis' value,
        # kept because the thesis' stiffness k_n = E A_p / d_p = 1.22e9 N/m [2.3] is built on
        # it; soda-lime glass is about 7e10 Pa (about a third). drumheat's scenes soften the
        # stiffness anyway (dem.stiffness), so E enters only the default stiffness and the
        # Hertz-type estimates. Conductivity 1.0 W/(m K) and poisson 0.25 are typical
        # soda-lime values (the thesis does not need them).
        Material("glass", 2500.0, 836.0, 1.0, 1.95e11, 0.25, 0.9,
                 "weigler-thermal-dem.md Table 2-1, 5-1 (E: the thesis' value, about 3x real "
                 "soda-lime glass); lambda, nu, eps typical"),
        # kraychev-tube-bundle.md issue 7 / section 3: wheat d = 4.07 mm, 1315 kg/m3,
        # 1520 J/(kg K). Conductivity and elastic data are typical literature values for grain.
        Material("wheat", 1315.0, 1520.0, 0.15, 3.0e8, 0.3, 0.9,
                 "kraychev-tube-bundle.md section 3; lambda, E, nu, eps typical"),
        # staltner-slag-particle.md section 9: solid-slag reference values (the digest gives
        # temperature-dependent fits; these constants are the room-temperature end).
        Material("slag", 2900.0, 1000.0, 1.5, 5.0e10, 0.25, 0.9,
                 "staltner-slag-particle.md section 9 (constant approximation)"),
        # Steel for walls and tubes (not from a digest; typical carbon steel).
        Material("steel", 7850.0, 460.0, 50.0, 2.1e11, 0.3, 0.8, "typical carbon steel"),
    ]
}


@dataclass(frozen=True)
class Gas:
    """Gas properties used by contact-conduction and convection models, SI units.

    Attributes
    ----------
    name : str
    conductivity : float
        W/(m K).
    heat_capacity : float
        Specific isobaric heat capacity c_p, J/(kg K).
    molar_mass : float
        kg/kmol.
    accommodation_constant : float
        The constant C in the accommodation-coefficient correlation
        ``log10(1/gamma - 1) = 0.6 - (1000 K / T + 1) / C`` (weigler-thermal-dem.md, App. A3).
    source : str
    """

    name: str
    conductivity: float
    heat_capacity: float
    molar_mass: float
    accommodation_constant: float
    source: str = ""


#: Dry air at 30 degC and 1 atm: weigler-thermal-dem.md, Table 8-1.
GASES: dict[str, Gas] = {
    "air": Gas("air", 0.0266, 1009.0, 28.96, 2.8, "weigler-thermal-dem.md Table 8-1 (30 degC)"),
}

#: Universal gas constant, J/(kmol K) (weigler-thermal-dem.md, Table 8-1).
R_UNIVERSAL = 8314.0


def material(name: str, **overrides: float) -> Material:
    """Look up a material by name, optionally overriding properties.

    Parameters
    ----------
    name : str
        One of ``MATERIALS`` (aluminium, glass, wheat, slag, steel).
    **overrides
        Property values replacing the library's (``density=2650.0`` ...).

    Raises
    ------
    KeyError
        If the name is unknown (the message lists the known ones).
    """
    try:
        base = MATERIALS[name]
    except KeyError:
        raise KeyError(f"unknown material {name!r}; known: {', '.join(sorted(MATERIALS))}") from None
    return replace(base, **overrides) if overrides else base


def gas(name: str = "air", **overrides: float) -> Gas:
    """Look up a gas by name (only ``"air"`` so far), optionally overriding properties."""
    try:
        base = GASES[name]
    except KeyError:
        raise KeyError(f"unknown gas {name!r}; known: {', '.join(sorted(GASES))}") from None
    return replace(base, **overrides) if overrides else base
