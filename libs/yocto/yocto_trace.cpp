// yocto_trace: implementation (in progress)
