"""The nodes' throttled logging takes errors and warnings of several kinds in any order."""
from freejoint_common.node_tools import Throttle
import rclpy.logging


def test_an_error_then_a_warning_through_one_throttle_are_both_logged():
    logger = rclpy.logging.get_logger('throttle_test')
    logged = []

    def error(text):
        logged.append(('error', text))
        return logger.error(text)

    def warn(text):
        logged.append(('warn', text))
        return logger.warning(text)

    throttle = Throttle(period=10.0)
    throttle(logger.error, 'refused', 'a refused command')
    throttle(logger.warning, 'behind', 'behind the wall clock')
    throttle(logger.error, 'refused', 'suppressed: same kind within the period')
    throttle(error, 'other', 'another error')
    throttle(warn, 'stale', 'a stale setpoint')
    assert logged == [('error', 'another error'), ('warn', 'a stale setpoint')]
