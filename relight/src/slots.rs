//! A buffer of columns laid end to end, each written once by the thread
//! that claims it and read by any thread once it is published: the arena
//! decodes columns on first use into the one contiguous layout a frame
//! streams fastest (per-column allocations measured 8–12 % slower frames at
//! 256², N = 200, on two threads).
//!
//! A part's state goes `EMPTY → CLAIMED → READY` (or back to `EMPTY` when
//! its writer fails). Only the thread whose compare-exchange moved it to
//! `CLAIMED` writes the part; a `READY` part is never written again and is
//! read after an `Acquire` load of its state, which pairs with the writer's
//! `Release` store.
#![allow(unsafe_code)]

use std::cell::UnsafeCell;
use std::ops::Range;
use std::sync::atomic::{AtomicU8, Ordering};

const EMPTY: u8 = 0;
const CLAIMED: u8 = 1;
const READY: u8 = 2;

/// A zeroed buffer of `T` whose cells `Slots` hands out.
struct Cells<T>(Box<[UnsafeCell<T>]>);

impl<T: Copy + Default> Cells<T> {
    /// `len` default values. For the primitive types used here the zeroed
    /// buffer comes straight from the allocator (no page is touched until
    /// it is written).
    fn new(len: usize) -> Cells<T> {
        let cells: Box<[T]> = vec![T::default(); len].into_boxed_slice();
        // SAFETY: `UnsafeCell<T>` is `repr(transparent)` over `T`, so a
        // `[T]` and a `[UnsafeCell<T>]` of one length have one layout; the
        // box is moved, so nothing else refers to it.
        Cells(unsafe { Box::from_raw(Box::into_raw(cells) as *mut [UnsafeCell<T>]) })
    }

    /// SAFETY: no thread writes `range` while the slice lives.
    unsafe fn read(&self, range: Range<usize>) -> &[T] {
        let cells = &self.0[range];
        // SAFETY: the caller's guarantee; the cells are `T`s.
        unsafe { std::slice::from_raw_parts(UnsafeCell::raw_get(cells.as_ptr()), cells.len()) }
    }

    /// SAFETY: no other thread reads or writes `range` while the slice
    /// lives, and no other slice of it is live on this thread.
    #[allow(clippy::mut_from_ref)]
    unsafe fn write(&self, range: Range<usize>) -> &mut [T] {
        let cells = &self.0[range];
        // SAFETY: the caller's guarantee; the cells are `T`s.
        unsafe { std::slice::from_raw_parts_mut(UnsafeCell::raw_get(cells.as_ptr()), cells.len()) }
    }
}

/// Parts of two buffers, one part of each per column: `A`s of a length
/// each part sets (the entries), `B`s of one length for all (the block
/// offsets), with a state per part.
pub(crate) struct Slots<A, B> {
    a: Cells<A>,
    b: Cells<B>,
    /// Part `j` of `a` is `a[bounds[j]..bounds[j + 1]]`.
    bounds: Vec<usize>,
    /// `B`s per part.
    b_len: usize,
    state: Box<[AtomicU8]>,
}

// SAFETY: a part is written only by the one thread that claimed it (the
// compare-exchange in `claim` admits one) and read only once its state is
// READY, after which nothing writes it; the Release store of `publish` and
// the Acquire loads of `claim` and `get` order the writes before the reads.
unsafe impl<A: Send + Sync, B: Send + Sync> Sync for Slots<A, B> {}

/// The right to write one part, held by one thread until it publishes the
/// part or drops the claim (which frees the part for another try).
pub(crate) struct Claim<'a, A, B> {
    slots: &'a Slots<A, B>,
    part: usize,
    published: bool,
}

impl<A: Copy + Default, B: Copy + Default> Slots<A, B> {
    /// Parts with `a_lens` `A`s and `b_len` `B`s each, all empty.
    pub fn new(a_lens: impl IntoIterator<Item = usize>, b_len: usize) -> Slots<A, B> {
        let mut bounds = vec![0];
        for len in a_lens {
            bounds.push(bounds[bounds.len() - 1] + len);
        }
        let parts = bounds.len() - 1;
        Slots {
            a: Cells::new(bounds[parts]),
            b: Cells::new(parts * b_len),
            bounds,
            b_len,
            state: (0..parts).map(|_| AtomicU8::new(EMPTY)).collect(),
        }
    }

    fn ranges(&self, part: usize) -> (Range<usize>, Range<usize>) {
        (
            self.bounds[part]..self.bounds[part + 1],
            part * self.b_len..(part + 1) * self.b_len,
        )
    }

    /// Part `part` if published.
    pub fn get(&self, part: usize) -> Option<(&[A], &[B])> {
        if !self.is_ready(part) {
            return None;
        }
        let (a, b) = self.ranges(part);
        // SAFETY: the part is READY (Acquire), so no thread writes it any
        // more (see the `Sync` impl).
        Some(unsafe { (self.a.read(a), self.b.read(b)) })
    }

    /// Whether part `part` is published.
    pub fn is_ready(&self, part: usize) -> bool {
        self.state
            .get(part)
            .is_some_and(|s| s.load(Ordering::Acquire) == READY)
    }

    /// The claim of part `part`, or `None` once it is published (or out of
    /// range); waits while another thread holds it.
    pub fn claim(&self, part: usize) -> Option<Claim<'_, A, B>> {
        let state = self.state.get(part)?;
        loop {
            match state.compare_exchange(EMPTY, CLAIMED, Ordering::Acquire, Ordering::Acquire) {
                Ok(_) => {
                    return Some(Claim {
                        slots: self,
                        part,
                        published: false,
                    })
                }
                Err(READY) => return None,
                Err(_) => std::thread::yield_now(),
            }
        }
    }
}

impl<A: Copy + Default, B: Copy + Default> Claim<'_, A, B> {
    /// The claimed part of each buffer, to write.
    pub fn parts(&mut self) -> (&mut [A], &mut [B]) {
        let (a, b) = self.slots.ranges(self.part);
        // SAFETY: this thread holds the part's claim (state CLAIMED), so no
        // other thread reads or writes it, and `&mut self` makes these the
        // only live slices of it.
        unsafe { (self.slots.a.write(a), self.slots.b.write(b)) }
    }

    /// Publishes the part: from now on it is read, never written.
    pub fn publish(mut self) {
        self.published = true;
        self.slots.state[self.part].store(READY, Ordering::Release);
    }
}

impl<A, B> Drop for Claim<'_, A, B> {
    /// An unpublished claim frees the part for another try.
    fn drop(&mut self) {
        if !self.published {
            self.slots.state[self.part].store(EMPTY, Ordering::Release);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parts written on several threads at once, some twice over after a
    /// dropped claim, read back whole; a published part is not claimed
    /// again.
    #[test]
    fn parts_are_written_once_and_read_after_publishing() {
        let lens: Vec<usize> = (0..64).map(|j| j % 7 * 100).collect();
        let slots = Slots::<u32, u8>::new(lens.iter().copied(), 3);
        std::thread::scope(|s| {
            for t in 0..4u32 {
                let slots = &slots;
                s.spawn(move || {
                    for j in 0..64 {
                        if let Some(mut c) = slots.claim(j) {
                            c.parts().0.fill(j as u32 + 1000 * t);
                            c.parts().1.fill(t as u8);
                            if !(j + t as usize).is_multiple_of(5) {
                                let (a, b) = c.parts();
                                assert!(a.iter().all(|&v| v == j as u32 + 1000 * t));
                                a.fill(j as u32);
                                b.fill(j as u8);
                                c.publish();
                            }
                        }
                    }
                });
            }
        });
        for (j, &len) in lens.iter().enumerate() {
            if let Some((a, b)) = slots.get(j) {
                assert_eq!((a.len(), b.len()), (len, 3));
                assert!(a.iter().all(|&v| v == j as u32));
                assert!(b.iter().all(|&v| v == j as u8));
                assert!(slots.claim(j).is_none());
            } else {
                assert!(!slots.is_ready(j));
                let mut c = slots.claim(j).unwrap();
                c.parts().0.fill(j as u32);
                c.publish();
                assert_eq!(slots.get(j).unwrap().0.len(), len);
            }
        }
    }
}
