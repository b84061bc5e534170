//! Shared iceoryx2 process wrapper of the chain (work in progress).
