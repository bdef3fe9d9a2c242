"""GUIDE's explorer node, optionally with slam_toolbox (online async) and Nav2 beside it (each
found only when asked for, so the node alone needs neither installed).

    ros2 launch guide_ros explore.launch.py                                  # the node only
    ros2 launch guide_ros explore.launch.py slam:=true nav2:=true send_goals:=true use_sim_time:=true
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution, PythonExpression
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory("guide_ros")
    use_sim_time = LaunchConfiguration("use_sim_time")
    arguments = [
        DeclareLaunchArgument("params_file", default_value=os.path.join(share, "config", "guide.yaml"),
                              description="the explorer's parameters"),
        DeclareLaunchArgument("use_sim_time", default_value="false"),
        DeclareLaunchArgument("send_goals", default_value="false", description="send each next waypoint to Nav2"),
        DeclareLaunchArgument("planner", default_value="guide", description="a registered planner name"),
        DeclareLaunchArgument("slam", default_value="false", description="also launch slam_toolbox (online async)"),
        DeclareLaunchArgument("nav2", default_value="false", description="also launch Nav2's navigation stack"),
    ]
    explorer = Node(
        package="guide_ros", executable="explorer", name="guide_explorer", output="screen",
        parameters=[LaunchConfiguration("params_file"),
                    {"use_sim_time": PythonExpression(["'", use_sim_time, "' == 'true'"]),
                     "send_goals": PythonExpression(["'", LaunchConfiguration("send_goals"), "' == 'true'"]),
                     "planner": LaunchConfiguration("planner")}],
    )
    slam = IncludeLaunchDescription(
        PythonLaunchDescriptionSource(PathJoinSubstitution([FindPackageShare("slam_toolbox"), "launch",
                                                            "online_async_launch.py"])),
        launch_arguments={"use_sim_time": use_sim_time}.items(), condition=IfCondition(LaunchConfiguration("slam")))
    nav2 = IncludeLaunchDescription(
        PythonLaunchDescriptionSource(PathJoinSubstitution([FindPackageShare("nav2_bringup"), "launch",
                                                            "navigation_launch.py"])),
        launch_arguments={"use_sim_time": use_sim_time}.items(), condition=IfCondition(LaunchConfiguration("nav2")))
    return LaunchDescription([*arguments, slam, nav2, explorer])
