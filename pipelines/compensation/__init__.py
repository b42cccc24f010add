"""The papers' compensation experiments against a rig (``python -m pipelines.compensate``).

* :mod:`.settings` - the typed settings (one node per experiment);
* :mod:`.rig` - the plant behind a :class:`~.rig.RigBackend`, the recorder, the 10 ms tick;
* :mod:`.models` - identification whose inverse can reach what it will be asked for;
* :mod:`.seed001`, :mod:`.seed002`, :mod:`.seed000` - one experiment each (thesis section
  4.7, ViO-Com Table I, Tables 2-5 of the active-modelling paper);
* :mod:`.tables`, :mod:`.figures`, :mod:`.report_section` - tables, plots, the report's text
  and the headline numbers;
* :mod:`.experiments` - :func:`~.experiments.run`, the pure core: settings in, a
  :class:`~.result.CompensationResult` (tables, figures, metrics) out, no files, no MLflow.

The stage's edge (write, track, the command) is :mod:`pipelines.compensate`. This package's
``__init__`` imports nothing: :mod:`pipelines.schemas` imports :mod:`.settings` at start-up.
"""
