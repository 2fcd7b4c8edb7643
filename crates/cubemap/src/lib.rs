//! Reflector cube maps with reflection-point search (Estalella et al. 2005).
