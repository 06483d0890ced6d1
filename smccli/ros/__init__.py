"""The tree on a robot over ROS 1: ``smc run TREE --ros1`` (:mod:`~smccli.ros.node`, plain
Python, over the rospy layer :mod:`~smccli.ros.ros1`) and ``smc sim --ros1``, a scene as a
ROS robot (:mod:`~smccli.ros.sim_robot`). The library entry points are in
:mod:`~smccli.ros.run`; docs/on_a_robot.md walks a lab through it."""
