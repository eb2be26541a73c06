"""The physically meaningful range of every number a scenario holds.

The keys' declarations (:mod:`executive.schema.scene_keys`, :mod:`executive.scenario.keys`,
each task kind's ``keys``) use these: the readers reject a value outside its range with a message
naming the key path, the value and the range, and ``executive schema`` (docs/scenarios.md) states
the same ranges, from the same declarations. Units: metres, kilograms, seconds, degrees (as
written in the file). Lower bounds that are exclusive (``> 0``) are stated in the declarations.
"""

from __future__ import annotations

# --- scene (scenario_scene.py)
#: |x|, |y| of the table's, an object's, an obstacle's and a target's position (m).
POSITION_MAX = 10.0
#: Highest z of a body's or a target's centre (m).
HEIGHT_MAX = 5.0
#: Table top height above the floor (m): (0, 3].
TABLE_HEIGHT_MAX = 3.0
#: Table depth and width (m): (0, 10]; its top thickness (m): (0, 0.5].
TABLE_SIZE_MAX = 10.0
TABLE_THICKNESS_MAX = 0.5
#: Edge lengths and radii of objects and obstacles (m): [1 mm, 5 m] (objects at most 2 m).
BODY_SIZE_MIN = 0.001
OBSTACLE_SIZE_MAX = 5.0
OBJECT_SIZE_MAX = 2.0
#: Object mass (kg): [1 g, 50 kg].
MASS_MIN = 0.001
MASS_MAX = 50.0
#: An obstacle's own clearance (m): (0, 1] (the planner's margin and the collision d_safety for it).
CLEARANCE_MAX = 1.0
#: Sliding friction coefficient: [0.01, 5].
FRICTION_MIN = 0.01
FRICTION_MAX = 5.0
#: Any angle in degrees (yaw, roll, pitch, to_yaw, table yaw): [-360, 360].
ANGLE_MAX_DEG = 360.0

# --- uncertainty and scene variation (1-sigma)
#: Object and obstacle horizontal position (m): [0, 0.2].
POSITION_SIGMA_MAX = 0.2
#: Object yaw (deg): [0, 180].
YAW_SIGMA_MAX_DEG = 180.0
#: The robot's CoM estimate (m): [0, 0.1].
COM_SIGMA_MAX = 0.1
#: Relative errors (object mass, friction): [0, 1] (1 = 100 %).
RELATIVE_SIGMA_MAX = 1.0
#: perception_scale factors: (0, 10].
PERCEPTION_SCALE_MAX = 10.0

# --- risk
#: d_safety (m): (0, 1].
D_SAFETY_MAX = 1.0
#: Exponents of the collision and fall metrics: (0, 10].
EXPONENT_MAX = 10.0
#: Weights (risk.weights, the collision and grasp metrics' weights): [0, 100].
WEIGHT_MAX = 100.0
#: fall.circle_radius (m): (0, 1]; fall.sigmas: (0, 10].
FALL_RADIUS_MAX = 1.0
SIGMAS_MAX = 10.0
#: grasp.position_scale and position_max (m): (0, 0.5]; angle_scale and angle_max (deg): (0, 180].
GRASP_POSITION_MAX = 0.5
GRASP_ANGLE_MAX_DEG = 180.0
#: grasp.steepness: (0, 100].
STEEPNESS_MAX = 100.0
#: Severities and body-part factors: (0, 1000].
SEVERITY_MAX = 1000.0
#: guard.min_distance (m): [0, 0.5]; guard.lookahead_s (s): [0, 5]; guard.min_com_margin (m): [0, 0.3].
GUARD_DISTANCE_MAX = 0.5
LOOKAHEAD_MAX_S = 5.0
COM_MARGIN_MAX = 0.3
#: rollouts.count, min_count, batch: at most 1000; budget_s (s): (0, 3600]; jobs: [1, 256];
#: indifference (ordering units): [0, 1000]; prior_weight (trials): [0, 10000].
ROLLOUTS_MAX = 1000
BUDGET_MAX_S = 3600.0
JOBS_MAX = 256
INDIFFERENCE_MAX = 1000.0
PRIOR_WEIGHT_MAX = 10000.0

# --- approval and trials
#: approval.timeout_s (s): (0, 86400] (a day).
TIMEOUT_MAX_S = 86400.0
#: trials.count: [1, 100000]; trials.seed: [0, 2**32 - 1].
TRIALS_MAX = 100_000
SEED_MAX = 2**32 - 1
