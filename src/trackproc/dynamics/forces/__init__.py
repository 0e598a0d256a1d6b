"""Force models beyond two-body + J2 (``--force full``): the Earth's gravity field in spherical
harmonics, Sun and Moon, solar radiation pressure, drag, relativity, an empirical
acceleration; summed by :class:`~trackproc.dynamics.forces.model.ForceModel` and integrated
with the variational equations by :mod:`trackproc.dynamics.forces.integrator`."""

from trackproc.dynamics.forces.gravity_field import GravityField
from trackproc.dynamics.forces.model import PARAMETERS, ForceModel, Spacecraft

__all__ = ["GravityField", "ForceModel", "Spacecraft", "PARAMETERS"]
