//! Control steps and the in-process runtime (work in progress).
