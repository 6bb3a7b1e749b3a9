//! The command-line pieces every example shares, for clap's derive: the `--device` option and
//! numbers written with digit separators. A file of its own so that the examples outside
//! `common` (autodiff, and `examples/prebuilt`, a crate of its own) include the same one.

#![allow(dead_code)] // each example uses its own subset

use std::fmt::Display;
use std::str::FromStr;

use warp_lang as wp;

/// `--device`: where an example runs.
#[derive(clap::Args, Debug, Clone)]
pub struct DeviceArg {
    /// The device to run on: `cpu`, `cuda:0`, `cuda:1`, ... [default: the preferred device:
    /// the first GPU, else the CPU]
    #[arg(long, value_name = "NAME")]
    pub device: Option<String>,
}

impl DeviceArg {
    /// Initialises warp-lang and returns the device named by `--device`, else the preferred
    /// one (the first GPU, or the CPU without one).
    pub fn get(&self) -> wp::Result<wp::Device> {
        wp::init();
        let dev = match &self.device {
            Some(name) => wp::get_device(name)?,
            None => {
                let dev = wp::get_preferred_device();
                // A GPU without NVRTC cannot compile kernels: the preferred device is then the
                // CPU, and the user is told why in one line (the library only logs it).
                if let Some(why) = wp::cpu_fallback_reason() {
                    eprintln!("warp-lang: {why}; running on the CPU");
                }
                dev
            }
        };
        // warp-lang logs its device banner rather than printing it: say where the example runs.
        println!("running on \"{dev}\": {}", dev.name());
        Ok(dev)
    }
}

/// A number that may be written with `_` digit separators (`--n 1_000_000`), for
/// `#[arg(value_parser = num::<T>)]`; clap names the option in the error.
pub fn num<T: FromStr>(text: &str) -> Result<T, String>
where
    T::Err: Display,
{
    text.replace('_', "")
        .parse()
        .map_err(|e: T::Err| e.to_string())
}
