// `sparse::mm` of blocks whose inner dimensions differ (Mat23 x Mat23: 3 columns, 2 rows) is a
// compile error naming both block types, not a run-time `Err`.
use warp_lang::Mat23;
use warp_runtime::sparse::{self, Bsr, MmWork};

fn main() {
    let dev = warp_lang::cpu();
    let a = Bsr::<Mat23>::zeros(2, 2, &dev).unwrap();
    let mut c = Bsr::<Mat23>::zeros(2, 2, &dev).unwrap();
    let _ = sparse::mm(1.0, &a, &a, 0.0, &mut c, &mut MmWork::new());
}
