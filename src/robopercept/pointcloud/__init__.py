"""Point clouds: the container, file I/O, filters, normals, clustering, plane segmentation,
and triangle meshes (reading, surface sampling, farthest point sampling)."""

from robopercept.pointcloud.cloud import PointCloud
from robopercept.pointcloud.clustering import euclidean_clusters
from robopercept.pointcloud.filters import (
    pass_through,
    radius_outlier_removal,
    statistical_outlier_removal,
    voxel_downsample,
)
from robopercept.pointcloud.io import (
    PcdData,
    check_cloud_path,
    read_pcd,
    read_point_cloud,
    write_point_cloud,
)
from robopercept.pointcloud.mesh import (
    TriangleMesh,
    chamfer_distance,
    farthest_point_sampling,
    normalize_unit_sphere,
    read_mesh,
    sample_surface,
)
from robopercept.pointcloud.normals import estimate_normals
from robopercept.pointcloud.segmentation import PlaneSegment, segment_plane, segment_planes

__all__ = [
    "PcdData",
    "PlaneSegment",
    "PointCloud",
    "TriangleMesh",
    "chamfer_distance",
    "check_cloud_path",
    "estimate_normals",
    "euclidean_clusters",
    "farthest_point_sampling",
    "normalize_unit_sphere",
    "pass_through",
    "radius_outlier_removal",
    "read_mesh",
    "read_pcd",
    "read_point_cloud",
    "sample_surface",
    "segment_plane",
    "segment_planes",
    "statistical_outlier_removal",
    "voxel_downsample",
    "write_point_cloud",
]
