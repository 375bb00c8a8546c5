"""
Read-backs tell the values in use.

``joint_names`` / ``joints`` not given are declared with the arm's, so ``ros2 param get``
answers the names the node uses.

One process: the node's parameters declared as the node declares them
(``NodeParameters``), no DDS traffic.
"""
import os

import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')


def _declared(schema, node, *args):
    """Return ``{joint_names, joints}`` as ``node`` declares them with ``args`` (ros args)."""
    import rclpy
    from freejoint_common.node_tools import NodeParameters
    context = rclpy.Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file',
                                      os.path.join(CONFIG, node + '.yaml'), *args])
    try:
        ros_node = rclpy.create_node('read_back', context=context,
                                     start_parameter_services=False, enable_rosout=False)
        try:
            NodeParameters(ros_node, schema)
            return {name: list(ros_node.get_parameter(name).value)
                    for name in ('joint_names', 'joints')}
        finally:
            ros_node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


@pytest.mark.parametrize('node', ['controller', 'sim'])
def test_joint_names_not_given_read_back_as_the_arms_and_given_ones_as_given(node):
    if node == 'controller':
        from freejoint_control.params import SCHEMA
    else:
        from freejoint_sim.params import SCHEMA
    assert _declared(SCHEMA, node) == {'joint_names': ['joint1', 'joint2', 'joint3'],
                                       'joints': ['joint1', 'joint2']}
    # the 4-link example: joint1 free, joints 2-4 driven (its URDF's names and order)
    four_link = ('--params-file', os.path.join(CONFIG, 'four_link', node + '.yaml'))
    assert _declared(SCHEMA, node, *four_link) == {
        'joint_names': ['joint1', 'joint2', 'joint3', 'joint4'],
        'joints': ['joint2', 'joint3', 'joint4']}
    # given: as given (the command's order may differ from the model's)
    assert _declared(SCHEMA, node, *four_link, '-p', 'joints:=[joint4, joint2, joint3]')[
        'joints'] == ['joint4', 'joint2', 'joint3']
