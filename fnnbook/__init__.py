"""Run the reproduction's notebooks as a checked, incremental pipeline.

>>> spec = load_spec("pipeline.yaml")            # doctest: +SKIP
>>> report = run(spec, "smoke", ["spiral"])       # doctest: +SKIP
"""

from fnnbook.params import check_task_parameters, read_parameters, resolve_parameters
from fnnbook.runner import Plan, RunReport, TaskOutcome, check, is_up_to_date, run
from fnnbook.spec import Part, PipelineError, PipelineSpec, Task, load_spec

__all__ = [
    "Part",
    "PipelineError",
    "PipelineSpec",
    "Plan",
    "RunReport",
    "Task",
    "TaskOutcome",
    "check",
    "check_task_parameters",
    "is_up_to_date",
    "load_spec",
    "read_parameters",
    "resolve_parameters",
    "run",
]
