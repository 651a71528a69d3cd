// yocto_scene: implementation (in progress)
