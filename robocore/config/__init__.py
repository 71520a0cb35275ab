"""robot.yaml: the model (:mod:`.model`), loading with line numbers (:mod:`.loader`),
cross-field checks (:mod:`.checks`) and the JSON Schema (:mod:`.schema`)."""

from robocore.config.loader import load_robot
from robocore.config.model import Component, Host, Robot

__all__ = ["Component", "Host", "Robot", "load_robot"]
