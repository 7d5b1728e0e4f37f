"""The survey: map a building's cards from walks recorded in rosbag2 bags (issue 13)."""
