"""The registered pyfunc as MLflow *models-from-code*.

:func:`pipelines.registry.log_pyfunc` hands this file (not a pickled object) to
``mlflow.pyfunc.log_model(python_model=<this file>)``. MLflow copies it into the logged model
and runs it when the model is loaded; ``set_model`` names the object that serves
``predict``. Nothing is pickled, so the model loads with any cloudpickle version, and what it
runs is readable in the model's artifacts.

The wrapper itself lives in :mod:`pipelines.registry`: the loading environment needs this
repository importable (any venv made by ``make venv``).
"""

from mlflow.models import set_model

from pipelines.registry import HysteresisPyfunc

set_model(HysteresisPyfunc())
