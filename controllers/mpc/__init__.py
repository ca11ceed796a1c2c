"""Visual predictive control (Allibert, Courtial & Chaumette, IEEE T-RO 2010) in CasADi.

- :mod:`controllers.mpc.prediction`: the local and global prediction models.
"""

from controllers.mpc.prediction import GlobalModel, LocalModel

__all__ = ["GlobalModel", "LocalModel"]
