"""
The simulator's plant engines (parameter ``engine``), built from its configuration.

* ``rk4``: classic RK4 at ``dt_sub`` (``freejoint_core.plant.Plant``): the closed-form
  3-link kernel for the paper's arm and any 3-link arm, Pinocchio's ABA
  (``freejoint_core.pin_plant.PinPlant``) for URDF arms of other lengths of chain, and
  ``freejoint_core.spatial_plant.SpatialPlant`` (Pinocchio's ABA of the URDF chain) for a
  spatial arm (``task_dim`` 3), the plant of the offline runner
  ``freejoint_core.spatial_offline``;
* ``mujoco``: MuJoCo's RK4 on the URDF (``freejoint_core.mujoco_plant.MujocoPlant``; the
  shipped ``paper_arm.urdf`` for the default arm; ``SpatialMujocoPlant`` for a spatial arm,
  equal to ``SpatialPlant`` to round-off, ``src/freejoint_sim/test/test_spatial_arm.py``).

Every engine holds the torque and one disturbance draw per control period with the same
seeded draws, so the engines differ only by their integration of the same equations:
closed loop over the paper's circle, MuJoCo = RK4 to 1e-6 mm in both cases
(``test/core/test_mujoco_plant.py``).  The choice for a URDF arm is
``freejoint_core.urdf_offline.make_plant``, the offline runner's.
"""

from freejoint_core.plant import Plant
from freejoint_core.urdf_offline import make_plant as urdf_plant


def make_plant(cfg):
    """
    Return a new plant for a simulator configuration, at ``cfg.q0``, at rest.

    Parameters
    ----------
    cfg : freejoint_sim.params.Config
        ``arm``, ``engine``, ``dt_sub``, ``dist_bound``, ``seed``, ``q0``,
        ``passive_damping`` (a spatial arm's).

    Returns
    -------
    freejoint_core.plant.PeriodPlant
        ``step(tau, dt)``, ``q``, ``qd``, ``stop()``, ``model.fk``.

    Raises
    ------
    FreejointValueError
        If the description cannot be built by the engine (naming ``arm``).

    """
    if cfg.arm.spatial is not None:
        # Pinocchio and MuJoCo imported for a spatial arm only
        if cfg.engine == 'mujoco':
            from freejoint_core.mujoco_plant import SpatialMujocoPlant as SpatialPlant
        else:
            from freejoint_core.spatial_plant import SpatialPlant
        return SpatialPlant(cfg.arm.spatial, cfg.dt_sub, dist_bound=cfg.dist_bound,
                            seed=cfg.seed, q0=cfg.q0, passive_damping=cfg.passive_damping)
    if cfg.engine == 'rk4' and cfg.arm.urdf_arm is None:
        return Plant(cfg.params, cfg.dt_sub, dist_bound=cfg.dist_bound, seed=cfg.seed,
                     q0=cfg.q0)
    return urdf_plant(cfg.arm.description(), cfg.engine, cfg.dt_sub, cfg.dist_bound, cfg.seed,
                      cfg.q0)
