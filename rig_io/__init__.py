"""Everything that touches the rig's world: the ``tsm-rig-log/1`` format, bags, importers
and the virtual rig that writes the same runs a real rig writes."""

from rig_io.errors import RigIOError
from rig_io.run import FORMAT, RawRun

__all__ = ["FORMAT", "RawRun", "RigIOError"]
