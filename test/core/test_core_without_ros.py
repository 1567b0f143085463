"""The core must import and work with rclpy (and every ROS module) blocked."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def test_core_imports_and_runs_with_rclpy_blocked():
    code = textwrap.dedent(
        """
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                root = name.split('.')[0]
                if root in ('rclpy', 'rosidl_runtime_py', 'tactile_descriptors_msgs', 'std_msgs',
                            'builtin_interfaces', 'launch', 'launch_ros', 'rosbags'):
                    raise ImportError('blocked for this test: ' + name)
        sys.meta_path.insert(0, Block())
        import numpy as np
        import tactile_descriptors_ros.core as core
        from tactile_descriptors_ros.core import (aggregation, alignment, colormap, contact, descriptors, display,
                                                  geometry, labels, learning, robot, scaling, tactile_image,
                                                  urdf, windowing)
        from tactile_descriptors_ros import errors
        r = robot.load_robot('shadow_hand')
        h = descriptors.hjorth(np.sin(np.arange(100) / 3.0), 100.0)
        assert h.quality == 0
        assert labels.LabelProtocol().add_label(0, 'cork').reason == 'unknown_exploration'
        tax = r.geometry.taxels(r, 'index')
        est = contact.locate_contact(tax, np.array([1]), np.array([1.0]), np.zeros(19), threshold_n=0.2, floor_n=0.05)
        assert est.in_contact and '<robot' in urdf.urdf_text(r)
        img = tactile_image.render(tactile_image.image_layout(geometry.layout_2d(tax.positions, tax.normals)),
                                   colormap.force_colours(est.taxel_force_n, 3.0))
        assert img.shape == (96, 96, 3)
        assert not [m for m in sys.modules if m.split('.')[0] in ('rclpy', 'std_msgs')]
        print('ok')
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
