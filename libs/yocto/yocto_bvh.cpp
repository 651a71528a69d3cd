// yocto_bvh: implementation (in progress)
