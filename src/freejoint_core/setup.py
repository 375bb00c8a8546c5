from setuptools import find_packages, setup

package_name = 'freejoint_core'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools', 'numpy'],
    # URDF arms: Pinocchio (pin) for their dynamics, MuJoCo for the mujoco engine.
    extras_require={'urdf': ['pin', 'mujoco']},
    zip_safe=True,
    maintainer='freejoint developers',
    maintainer_email='dev@freejoint.invalid',
    description='Arm model, robust control law, trajectory and singularity analysis (no ROS).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'offline = freejoint_core.offline:main',
        ],
    },
)
