"""ros2 launch simreal_nodes simreal.launch.py scene:=/path/to/scene.yaml [lossless:=false]

The same node set as `simreal launch SCENE.yaml` (computed by simreal_nodes.scene.graph), as
launch_ros Node actions, for users with a full ROS install.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context):
    import os

    from simreal_nodes.launch import thread_variables
    from simreal_nodes.scene.graph import required_nodes
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    # spec:NAME models are built here, before the nodes start (they only find them in the cache)
    scene = build_spec_models(load_scene(LaunchConfiguration("scene").perform(context)))
    lossless = LaunchConfiguration("lossless").perform(context).lower() == "true"
    # the libraries' thread pools as `simreal launch` sizes them (SIMREAL_THREADS, else the linear algebra's one
    # thread each; README "threads")
    pools = thread_variables(dict(os.environ))
    return [Node(package="simreal_nodes", executable=spec.name, name=spec.name, parameters=[spec.parameters],
                 output="screen", respawn=True, additional_env=pools) for spec in required_nodes(scene, lossless)]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("scene", description="scene YAML"),
        DeclareLaunchArgument("lossless", default_value="false"),
        OpaqueFunction(function=_nodes),
    ])
