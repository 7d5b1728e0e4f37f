"""The shipped robot_localization EKF configuration is what docs/robot_localization.md says."""

import numpy as np
from pattern_locator.resources import config_path
import yaml

CONFIG = yaml.safe_load(config_path('robot_localization_ekf.yaml').read_text())
PARAMS = CONFIG['ekf_filter_node']['ros__parameters']


def test_the_fixes_and_the_odometry_are_fused_in_the_map_frame():
    assert PARAMS['world_frame'] == PARAMS['map_frame'] == 'map'
    assert PARAMS['two_d_mode'] is False
    # The locator's covariance topic (relative, as the locator publishes it).
    assert PARAMS['pose0'] == 'robot_location/with_covariance'
    assert PARAMS['pose0_config'][:6] == [True] * 6 and not any(PARAMS['pose0_config'][6:])
    # Odometry: velocities only, the planar base's zero z/roll/pitch rates included.
    assert not any(PARAMS['odom0_config'][:6]) and all(PARAMS['odom0_config'][6:12])
    # Fixes are stamped with their image's time: the filter must take lagged data.
    assert PARAMS['smooth_lagged_data'] is True and PARAMS['history_length'] >= 0.5


def test_the_matrices_are_15_by_15_symmetric_and_positive():
    for name in ('process_noise_covariance', 'initial_estimate_covariance'):
        matrix = np.array(PARAMS[name], dtype=float).reshape(15, 15)
        assert np.allclose(matrix, matrix.T)
        assert np.all(np.linalg.eigvalsh(matrix) > 0.0), name
    for name in ('odom0_config', 'pose0_config'):
        assert len(PARAMS[name]) == 15 and all(isinstance(v, bool) for v in PARAMS[name])
