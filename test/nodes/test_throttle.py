"""The nodes' throttled logging takes errors and warnings of several kinds in any order."""
from freejoint_control.controller_node import Throttle as ControllerThrottle
from freejoint_sim.sim_node import Throttle as SimThrottle
import pytest
import rclpy.logging


@pytest.mark.parametrize('throttle_class', [SimThrottle, ControllerThrottle],
                         ids=['sim', 'controller'])
def test_an_error_then_a_warning_through_one_throttle_are_both_logged(throttle_class):
    logger = rclpy.logging.get_logger('throttle_test_%s' % throttle_class.__module__)
    logged = []

    def error(text):
        logged.append(('error', text))
        return logger.error(text)

    def warn(text):
        logged.append(('warn', text))
        return logger.warning(text)

    throttle = throttle_class(period=10.0)
    throttle(logger.error, 'refused', 'a refused command')
    throttle(logger.warning, 'behind', 'behind the wall clock')
    throttle(logger.error, 'refused', 'suppressed: same kind within the period')
    throttle(error, 'other', 'another error')
    throttle(warn, 'stale', 'a stale setpoint')
    assert logged == [('error', 'another error'), ('warn', 'a stale setpoint')]
