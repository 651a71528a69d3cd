// yocto_hair: implementation (in progress)
