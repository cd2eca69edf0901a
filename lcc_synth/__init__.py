"""lcc_synth: design and test Leading Cruise Control (LCC) controllers.

The package follows the paper "Leading Cruise Control in Mixed Traffic Flow" (Wang, Zheng,
Chen, Xu, Li). Data flows one way: problem file -> model -> controller -> simulator ->
metrics -> recording / figures.
"""

from lcc_synth.errors import ConfigError

__all__ = ["ConfigError"]
__version__ = "0.1.0"
