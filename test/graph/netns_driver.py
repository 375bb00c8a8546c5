"""
Inside the planner's network namespace (test_netns.py): start the run, wait for its end.

Once the recorder's ``~/status`` says every graph topic has a matched publisher it calls
the planner's ``~/plan_circle`` with the circle of ``planner.yaml``, waits for the state of
step ``ticks`` on ``joint_states``, then until the recorder's count stays steady, and prints
``driver: drained <count>``.  Any failure: one line ``driver: error: ...``, exit 1.

Usage: netns_driver.py PLANNER_YAML TICKS
"""
import sys
import time


def main(planner_yaml, ticks):
    from freejoint_common.contract import JOINT_STATES, to_ns
    from freejoint_msgs.srv import PlanCircle
    from freejoint_planner.params import SCHEMA
    from freejoint_tools.recorder import REPAIR_QUIET, wait_drained
    import rclpy
    from std_srvs.srv import Trigger

    rclpy.init()
    node = rclpy.create_node('netns_driver')

    def spin(seconds=0.05):
        rclpy.spin_once(node, timeout_sec=seconds)

    def call(client, request, timeout):
        if not client.wait_for_service(timeout_sec=timeout):
            return None
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
        return future.result() if future.done() else None

    last = [0]

    def on_state(msg):
        last[0] = max(last[0], to_ns(msg.header.stamp))

    node.create_subscription(JOINT_STATES.msg_type, '/' + JOINT_STATES.name, on_state,
                             JOINT_STATES.qos)
    status = node.create_client(Trigger, '/recorder/status')
    deadline = time.monotonic() + 120.0
    answer = None
    while answer is None or not answer.success:
        if time.monotonic() > deadline:
            print('driver: error: the recorder did not match every graph topic within 120 s '
                  '(%s)' % (answer.message if answer else 'no answer'), flush=True)
            return 1
        answer = call(status, Trigger.Request(), 10.0)
        spin(0.2)
    settle = time.monotonic() + 1.0   # the writers' side of the match can lag a little
    while time.monotonic() < settle:
        spin()
    circle = SCHEMA.yaml_values(planner_yaml)     # the file over the schema's defaults
    plan = node.create_client(PlanCircle, '/freejoint_planner/plan_circle')
    answer = call(plan, PlanCircle.Request(
        centre=[float(v) for v in circle['centre']], radius=float(circle['radius']),
        duration=float(circle['duration']), start_angle=float(circle['start_angle']),
        direction=int(circle['direction']), execute=True), 30.0)
    if answer is None or not answer.accepted:
        print('driver: error: plan_circle: %s' % (answer.reason if answer else 'no answer'),
              flush=True)
        return 1
    print('driver: plan accepted', flush=True)
    end_ns = ticks * 1_000_000
    deadline = time.monotonic() + 240.0
    while last[0] < end_ns:
        if time.monotonic() > deadline:
            print('driver: error: the state of step %d did not come within 240 s (last %d ns)'
                  % (ticks, last[0]), flush=True)
            return 1
        spin()

    def read_status():
        result = call(status, Trigger.Request(), 5.0)
        return result.message if result else ''

    count, _ = wait_drained(read_status, REPAIR_QUIET, 60.0, spin)
    print('driver: drained %s' % count, flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1], int(sys.argv[2])))
