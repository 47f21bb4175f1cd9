"""bagfault/report/fields.py: orientations are plotted as the angle a fault changes, not as quaternion parts."""

from __future__ import annotations

import math

import numpy as np
from support.html_check import figures, rendered, report_of

from bagfault.demo import synthetic


def test_a_yaw_bias_is_plotted_as_yaw_in_degrees_across_the_half_turn(tmp_path):
    """The synthetic robot turns at 0.1 rad/s, so its yaw passes +-180 deg at 31.4 s, where a quaternion with
    w >= 0 flips the sign of z: a 5 deg bias from 25 s to 38 s must show as 5 deg all along (after - before),
    and the series as the robot's yaw (synthetic.odom_pose, wrapped to +-180)."""
    page = report_of(tmp_path, [('/odom_raw', 'nav_msgs/msg/Odometry', 20.0)], 40.0, """
        injectors:
          - {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: turned, injector_id: odom, start: 25.0, duration: 13.0, config: {yaw_bias_deg: 5.0}}
    """)
    drawn = figures(page)
    assert not [name for name in drawn if 'orientation.' in name]
    figure = drawn['field:/odom:pose.pose.orientation:yaw']
    assert figure['layout']['yaxis']['title']['text'] == 'yaw of pose.pose.orientation (deg)'
    before, after, difference = figure['data'][:3]
    times = np.array(before['x'])
    expected = np.degrees([synthetic.odom_pose(t)[2] for t in times])
    assert np.allclose(before['y'], expected, atol=1e-9)
    assert min(before['y']) < -170 and max(before['y']) > 170  # the series does cross the half turn
    inside = [d for t, d in zip(difference['x'], difference['y'], strict=True) if 25.0 <= t < 38.0]
    outside = [d for t, d in zip(difference['x'], difference['y'], strict=True) if t < 25.0 or t >= 38.0]
    assert len(inside) == 13 * 20 and all(abs(d - 5.0) < 1e-6 for d in inside)
    assert outside and all(abs(d) < 1e-6 for d in outside)
    biased = [(t, a) for t, a in zip(after['x'], after['y'], strict=True) if 25.0 <= t < 38.0]
    # the robot's yaw 0.1 t rad plus 5 deg, on the circle (-180, 180]: 30 s is 176.9 -> -178.1 deg
    assert all(math.isclose(a, (math.degrees(0.1 * t) + 5 + 180) % 360 - 180, abs_tol=1e-6) for t, a in biased)
    assert any(a < -170 for _, a in biased) and any(a > 170 for _, a in biased)
    assert math.isclose(after['y'][0], before['y'][0])  # before the fault: untouched
    body = rendered(page, tmp_path / 'profile')
    assert body['errors'] == '0' and int(body['figures']) == len(drawn)
