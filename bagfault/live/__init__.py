"""Live mode: the offline injectors, scheduler and oracles on a running ROS 2 graph (rclpy).

`session` holds everything that does not need rclpy and is tested without a
graph; `node`, `player` and `recorder` wire it to rclpy. rclpy comes from the
optional extra `live` (`pip install 'bagfault[live]'`).
"""

from __future__ import annotations

from pathlib import Path

from bagfault.errors import LiveError

LOOPBACK_PROFILE = Path(__file__).with_name('fastdds_loopback.xml')


def rclpy_available() -> bool:
    """True when rclpy imports here."""
    try:
        import rclpy  # noqa: F401, PLC0415
    except ImportError:
        return False
    return True


def require_rclpy() -> None:
    """Fail with one clear line when rclpy is not importable."""
    try:
        import rclpy  # noqa: F401, PLC0415
    except ImportError as exc:
        raise LiveError(
            f"live mode needs rclpy ({exc}); install the extra: pip install 'bagfault[live]' "
            'or source a ROS 2 Jazzy installation'
        ) from None

__all__ = [  # its own functions, then its public modules
    'LOOPBACK_PROFILE',
    'anchor',
    'clockwarp',
    'delay',
    'diagnostics',
    'events',
    'graph',
    'losses',
    'node',
    'pacer',
    'params',
    'player',
    'proxy',
    'rclpy_available',
    'recorder',
    'recording',
    'require_rclpy',
    'ros',
    'runtime',
    'session',
    'sink',
    'trigger',
    'viewing',
]
