"""
freejoint_tools.harness.ParameterCalls: a parameter request left unanswered is sent again.

The stand-in is a node of this process offering the six parameter services of ``/standin``
itself: it counts the requests of each service and leaves the ones it is told to withhold
unanswered (their callback blocks until the test ends, as a response lost by the
middleware never arrives), so the resend path runs for real, with bounded waits.
"""
import threading
import time

import pytest

pytestmark = pytest.mark.ros

TARGET = '/standin'


class StandIn:
    """The parameter services of ``/standin``, withholding the answers asked for."""

    def __init__(self, withhold):
        import rclpy
        from rcl_interfaces import srv
        from rclpy.callback_groups import ReentrantCallbackGroup
        from rclpy.executors import MultiThreadedExecutor
        self.withhold = withhold        # {service: request numbers (1, 2, ...) unanswered}
        self.requests = {}
        self.release = threading.Event()
        self.lock = threading.Lock()
        self.node = rclpy.create_node('standin', start_parameter_services=False)
        group = ReentrantCallbackGroup()
        for name, srv_type in [('list_parameters', srv.ListParameters),
                               ('get_parameters', srv.GetParameters),
                               ('set_parameters', srv.SetParameters),
                               ('get_parameter_types', srv.GetParameterTypes),
                               ('describe_parameters', srv.DescribeParameters),
                               ('set_parameters_atomically', srv.SetParametersAtomically)]:
            self.node.create_service(srv_type, TARGET + '/' + name, self._answer(name),
                                     callback_group=group)
        # A withheld request holds a thread until the end: room for a few of them.
        self.executor = MultiThreadedExecutor(num_threads=12)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _answer(self, name):
        from rcl_interfaces.msg import ParameterType, ParameterValue, SetParametersResult

        def callback(request, response):
            with self.lock:
                number = self.requests[name] = self.requests.get(name, 0) + 1
            if number in self.withhold.get(name, ()):
                self.release.wait(60.0)
                return response
            if name == 'set_parameters':
                response.results = [SetParametersResult(
                    successful=True, reason='answered request %d' % number)
                    for _ in request.parameters]
            elif name == 'get_parameters':
                response.values = [ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                  string_value='value of ' + n)
                                   for n in request.names]
            return response
        return callback

    def close(self):
        """Answer the withheld requests (to nobody) and stop the stand-in."""
        self.release.set()
        self.executor.shutdown(timeout_sec=10.0)
        self.thread.join(10.0)
        self.node.destroy_node()


@pytest.fixture
def standin_of(ros_node):
    made = []

    def make(withhold, kind=None):
        made.append((kind or StandIn)(withhold))
        return made[-1]
    yield make
    for standin in made:
        standin.close()


def test_a_set_whose_answer_is_lost_is_sent_again_and_the_second_answer_returned(
        ros_node, standin_of):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    standin = standin_of({'set_parameters': {1}})
    calls = ParameterCalls(ros_node, TARGET, timeout=10.0, resend=0.5)
    start = time.monotonic()
    (res,) = calls.set_parameters([Parameter('K', value=[40.0, 60.0])])
    took = time.monotonic() - start
    assert res.successful
    # The first request was taken and never answered: the answer is a later request's,
    # sent no earlier than one patience after the first.
    assert standin.requests['set_parameters'] >= 2
    assert res.reason.startswith('answered request ') and res.reason != 'answered request 1'
    assert calls.sent >= 2 and took >= 0.5
    # The next call goes out once and its first request is answered.
    answered = standin.requests['set_parameters']
    (res,) = calls.set_parameters([Parameter('K', value=[40.0, 60.0])])
    assert res.reason == 'answered request %d' % (answered + 1) and calls.sent == 1


def test_values_come_back_as_plain_python_in_the_order_asked(ros_node, standin_of):
    from freejoint_tools.harness import ParameterCalls
    standin_of({})
    calls = ParameterCalls(ros_node, TARGET, timeout=10.0, resend=2.0)
    values = calls.get_values(['b', 'a'])
    assert list(values.items()) == [('b', 'value of b'), ('a', 'value of a')]


def test_a_node_that_never_answers_fails_within_the_timeout_naming_node_and_call(
        ros_node, standin_of, wait):
    from freejoint_tools.harness import ParameterCalls
    standin = standin_of({'get_parameters': set(range(1, 20))})
    calls = ParameterCalls(ros_node, TARGET, timeout=2.0, resend=0.5)
    calls.calls.spin_until(calls.client.services_are_ready, 10.0)
    start = time.monotonic()
    with pytest.raises(TimeoutError) as err:
        calls.get_parameters(['K'])
    took = time.monotonic() - start
    assert 2.0 <= took < 4.0
    assert str(err.value).startswith('no answer from /standin/get_parameters within 2 s (')
    # One request every 0.5 s from 0 to 2 s: four (three if the spin overran, loaded).
    assert calls.sent in (3, 4)
    wait(lambda: standin.requests.get('get_parameters') == calls.sent, 10.0,
         'the stand-in to have taken every request sent')


def test_no_such_node_fails_within_the_timeout_naming_it(ros_node):
    from freejoint_tools.harness import ParameterCalls
    calls = ParameterCalls(ros_node, '/nobody_here', timeout=1.0, resend=0.5)
    start = time.monotonic()
    with pytest.raises(TimeoutError, match='^no parameter services of /nobody_here within '
                                           '1 s$'):
        calls.set_parameters([])
    assert time.monotonic() - start < 3.0


class TriggerStandIn(StandIn):
    """A ``/standin/reset`` (std_srvs/Trigger) that withholds the answers asked for."""

    def __init__(self, withhold):
        import rclpy
        from rclpy.callback_groups import ReentrantCallbackGroup
        from rclpy.executors import MultiThreadedExecutor
        from std_srvs.srv import Trigger
        self.withhold, self.requests = withhold, 0
        self.release, self.lock = threading.Event(), threading.Lock()
        self.node = rclpy.create_node('standin_trigger')
        self.node.create_service(Trigger, TARGET + '/reset', self._answer,
                                 callback_group=ReentrantCallbackGroup())
        self.executor = MultiThreadedExecutor(num_threads=6)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _answer(self, request, response):
        with self.lock:
            self.requests += 1
            number = self.requests
        if number in self.withhold:
            self.release.wait(30.0)
            return response
        response.success, response.message = True, 'answered request %d' % number
        return response


def test_an_idempotent_service_call_is_sent_again_when_its_answer_is_lost(
        ros_node, standin_of):
    from freejoint_tools.harness import ServiceCalls
    from std_srvs.srv import Trigger
    standin = standin_of({1, 3}, TriggerStandIn)
    calls = ServiceCalls(ros_node)
    answer = calls.call(Trigger, TARGET + '/reset', Trigger.Request(), 10.0, resend=0.5)
    assert answer is not None and answer.message == 'answered request 2'
    # Without resend the withheld request is all there is: no answer within the timeout.
    start = time.monotonic()
    assert calls.call(Trigger, TARGET + '/reset', Trigger.Request(), 1.5) is None
    assert 1.5 <= time.monotonic() - start < 4.0 and standin.requests == 3
