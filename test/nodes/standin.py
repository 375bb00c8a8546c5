"""
What every stand-in node script of the tests shares: spin one node until stopped.

The scripts run as ``python test/nodes/<script>.py``, so this module, next to them, is on
their ``sys.path``.
"""
import rclpy
from rclpy.executors import ExternalShutdownException


def spin(node):
    """
    Spin ``node`` until SIGINT/SIGTERM (or the context ends), then destroy it and shut down.

    An exception raised by a callback while the context is still valid propagates (the
    test then sees the traceback in the script's log); one raised because the context was
    shut down under a running callback is the end of the run.
    """
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
