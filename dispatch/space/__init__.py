"""The concrete spaces: the voxel world (with its PyBullet mirror) and the road network (with
congestion), and the drivers that move a vehicle through each."""
