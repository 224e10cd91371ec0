//! netsim: a deterministic network simulator in virtual time.
//! (Being built: see issue "netsim".)
