// yocto_sceneio: implementation (in progress)
