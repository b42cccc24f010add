"""The virtual rig: physics, sensors, excitations, effects and the standard campaign.

See ``docs/virtual-rig.md``. Public API: :func:`simulate_run`, :class:`VirtualRig`,
:func:`make_excitation`, :func:`standard_campaign`, :data:`EFFECT_NAMES`, :data:`RIG_NAMES`.
"""

from rig_io.virtual.campaign import standard_campaign
from rig_io.virtual.effects import EFFECT_NAMES
from rig_io.virtual.excitations import EXCITATION_KINDS, make_excitation
from rig_io.virtual.model import RIG_NAMES, TSMParams
from rig_io.virtual.rig import VirtualRig, simulate_run

__all__ = ["EFFECT_NAMES", "EXCITATION_KINDS", "RIG_NAMES", "TSMParams", "VirtualRig",
           "make_excitation", "simulate_run", "standard_campaign"]
