"""zooctl-ray: the ``ray`` executor (see `zooctl_ray.executor`)."""
