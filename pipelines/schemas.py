"""Typed configuration nodes (Hydra structured configs).

A setting whose meaning lives in a dataclass of the library is registered here as that
dataclass, so its defaults and types are written once: the YAML under ``conf/`` selects the
node in its defaults list and only overrides what differs, and a misspelt or mistyped
override (``workflow.max_efects=2``, ``workflow.max_effects=two``) fails when the config is
composed instead of being ignored.
"""

from __future__ import annotations

from hydra.core.config_store import ConfigStore

from hysteresis.discrepancy.workflow import WorkflowSettings

#: Config group of the discrepancy workflow's knobs (``conf/discrepancy.yaml``:
#: ``- workflow_schema@workflow: workflow``).
WORKFLOW_GROUP = "workflow_schema"


def register() -> None:
    """Store every schema node in Hydra's ConfigStore (idempotent)."""
    ConfigStore.instance().store(group=WORKFLOW_GROUP, name="workflow", node=WorkflowSettings)
