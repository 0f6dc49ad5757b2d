"""The numba runtime every process's engine shares: compiled primitives (``kernels``), a
kernel's arguments packed into one table (``packed``) and declared as named records
(``schema``), blocks of lanes stepped on threads (``blocks``) and the lanes' counter-based
normals (``normals``).

This wing imports no process and no gymnasium; the agents never import it (they read a
process's model through ``machining_envs.<process>.plant``).
"""
