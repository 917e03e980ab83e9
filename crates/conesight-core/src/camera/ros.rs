//! ROS `camera_info` YAML loading. Filled in by the camera-config work.
