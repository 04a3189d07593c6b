"""2-D graph SLAM, headless (numpy, scipy and numba only; never imports the simulator).

Back end: SE(2) helpers (:mod:`.se2`), pose graphs and their sparse Levenberg-Marquardt
optimiser (:mod:`.posegraph`), g2o files (:mod:`.g2o`) and the Kümmerle et al. relative-pose
metric (:mod:`.evaluate`).
"""

from agvsim.slam.evaluate import (
    RelationErrors,
    evaluate_relations,
    format_relation_errors,
    load_relations,
    load_trajectory,
)
from agvsim.slam.g2o import G2OFormatError, load_g2o, save_g2o
from agvsim.slam.posegraph import (
    Initialisation,
    OptimizeResult,
    PoseGraph,
    RobustKernel,
    chi2,
    optimize,
)
from agvsim.slam.se2 import between, compose, inverse, wrap_angle

__all__ = [
    # back end
    "G2OFormatError",
    "Initialisation",
    "OptimizeResult",
    "PoseGraph",
    "RelationErrors",
    "RobustKernel",
    "between",
    "chi2",
    "compose",
    "evaluate_relations",
    "format_relation_errors",
    "inverse",
    "load_g2o",
    "load_relations",
    "load_trajectory",
    "optimize",
    "save_g2o",
    "wrap_angle",
]

# front end: log reading, scan matching, submaps, loop closure, the online SLAM, offline runs
from agvsim.scan import LaserScan  # noqa: E402
from agvsim.slam.carmen import CarmenFormatError, CarmenLog, read_carmen  # noqa: E402
from agvsim.slam.graph_slam import GraphSlam, SlamConfig  # noqa: E402
from agvsim.slam.mapping import OccupancyMap  # noqa: E402
from agvsim.slam.offline import OfflineResult, run_offline  # noqa: E402

__all__ += [
    "CarmenFormatError",
    "CarmenLog",
    "GraphSlam",
    "LaserScan",
    "OccupancyMap",
    "OfflineResult",
    "SlamConfig",
    "read_carmen",
    "run_offline",
]
