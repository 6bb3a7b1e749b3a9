//! The host-object recipe, held to the kernel macro's object table: every row (a kernel
//! parameter type such as `HashGrid`, or a query state such as `HashGridQuery`) has what the
//! generated code relies on, so that a new object missing one of its few pieces fails here
//! with the piece named, not in a user's kernel.
//!
//! - A parameter row's type is a `HostObject` at `wp::Name` and `wp::prelude::Name`, whose
//!   `View` is the row's view in `warp_core::objects` (what the generated CPU code names).
//! - Every row's view or state has its adjoint placeholder (`Adjoint`).
//! - With CUDA: the row's section header defines its C++ type, tagged `wp_object_tag` (the
//!   C++ adjoint placeholder).

use std::marker::PhantomData;
use warp_lang as wp;
use wp::__private::adjoint::Adjoint;
use wp::objects::HostObject;

/// `O` is a host object whose CPU view is `V`.
fn host_object<O: HostObject<View = V>, V>() -> &'static str {
    std::any::type_name::<O>()
}

/// `T` has an adjoint placeholder.
fn adjoint<T: Adjoint>() -> &'static str {
    std::any::type_name::<T>()
}

/// One row's compile-time checks; returns the row's `(name, C++ type, section, param)`.
macro_rules! row {
    ($name:ident, param, plain, $rust:ident, $cuda:literal, $section:literal) => {{
        let _: PhantomData<wp::$name> = PhantomData::<wp::prelude::$name>;
        host_object::<wp::$name, wp::__private::objects::$rust>();
        adjoint::<wp::__private::objects::$rust>();
        (stringify!($name), $cuda, $section, true)
    }};
    // A type generic over its element: checked at one element (the others are the same impl).
    ($name:ident, param, elem, $rust:ident, $cuda:literal, $section:literal) => {{
        let _: PhantomData<wp::$name<f32>> = PhantomData::<wp::prelude::$name<f32>>;
        host_object::<wp::$name<f32>, wp::__private::objects::$rust<f32>>();
        adjoint::<wp::__private::objects::$rust<f32>>();
        (stringify!($name), $cuda, $section, true)
    }};
    ($name:ident, state, plain, $rust:ident, $cuda:literal, $section:literal) => {{
        adjoint::<wp::__private::objects::$rust>();
        (stringify!($name), $cuda, $section, false)
    }};
}

macro_rules! rows {
    ($(($($row:tt)*))*) => {
        vec![$(row!($($row)*)),*]
    };
}

/// Every row of the kernel macro's object table, checked at compile time by `row!`.
fn object_rows() -> Vec<(&'static str, &'static str, &'static str, bool)> {
    wp::__private::__object_rows!(rows)
}

/// The checks are `row!`'s, at compile time; this holds the table to having rows of both
/// roles, each named once (a table `row!` saw nothing of would pass vacuously).
#[test]
fn every_object_row_has_its_pieces() {
    let rows = object_rows();
    let params = rows.iter().filter(|r| r.3).count();
    assert!(params > 0 && params < rows.len(), "{rows:?}");
    for (i, r) in rows.iter().enumerate() {
        assert!(rows[..i].iter().all(|o| o.0 != r.0), "{} twice", r.0);
    }
}

#[cfg(feature = "cuda")]
#[test]
fn every_object_row_has_its_cpp_type() {
    for (name, cuda, section, _) in object_rows() {
        let header = format!("wp_{section}.h");
        let text = header_text(&header)
            .unwrap_or_else(|| panic!("{name}: section `{section}` has no header {header}"));
        let ty = cuda.strip_prefix("wp::").expect("a wp:: type");
        let def = format!("struct {ty} {{");
        let at = text
            .find(&def)
            .unwrap_or_else(|| panic!("{name}: {header} defines no `{def}`"));
        let body = &text[at..at + text[at..].find("\n};").expect("the struct ends")];
        assert!(
            body.contains("typedef void wp_object_tag;"),
            "{name}: {ty} in {header} lacks the `wp_object_tag` the adjoint library needs"
        );
    }
}

/// A CUDA library header's text, by file name.
#[cfg(feature = "cuda")]
fn header_text(name: &str) -> Option<&'static str> {
    warp_cuda::HEADERS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}
