"""The core is ROS-free: importing it must not load rclpy."""

import subprocess
import sys

CORE = ['pattern', 'camera', 'geometry', 'detector', 'pose_exact', 'pose_paper', 'locate',
        'printable', 'render', 'baselines', 'bench', 'demo', 'paper_setup', 'cli',
        'image_codec', 'head', 'building', 'localizer', 'bench_node', 'bags', 'overlay',
        'node_process', 'visca', 'visca_emulator', 'visca_transport', 'visca_camera',
        'tracking', 'sim_world', 'zoom_table', 'head_loop', 'bench_tracking', 'demo_system']


def test_core_modules_do_not_import_rclpy():
    code = ('import sys\n'
            + ''.join(f'import pattern_locator.{name}\n' for name in CORE)
            + 'bad = sorted(m for m in sys.modules if m.split(".")[0] in '
              '("rclpy", "rosidl_runtime_py", "sensor_msgs"))\n'
              'print(",".join(bad))\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == ''
