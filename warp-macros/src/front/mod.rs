//! Front end: Rust syntax (syn) to the IR, with the language subset's checks and the type
//! rules. Errors carry the user's span and are gathered, many at once (one per statement).

pub mod attrs;
pub mod generics;
pub mod lower;
pub mod signature;
