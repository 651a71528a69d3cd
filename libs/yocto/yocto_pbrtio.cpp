// yocto_pbrtio: implementation (in progress)
