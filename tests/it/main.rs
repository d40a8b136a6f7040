//! The facade's end-to-end tests, one binary (each file a module).

mod pipeline;
