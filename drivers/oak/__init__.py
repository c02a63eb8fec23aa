"""Luxonis OAK cameras through depthai as video-centroid mocap cameras."""
