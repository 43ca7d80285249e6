//! The replay buffer shared by the off-policy agents: flat arrays preallocated at full capacity,
//! a ring once full, uniform sampling with replacement into a reusable [`Batch`].

use crate::base::rng::Rng;
use crate::nn::copy_row;
use crate::{Error, Result};

/// Transitions `(s, a, r, s', terminal)`; `terminal` is 1 only when the episode ended in a
/// terminal state (target reached), not on truncation, so critics bootstrap through time limits.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayBuffer {
    capacity: usize,
    obs_dim: usize,
    act_dim: usize,
    len: usize,
    /// Next slot to write.
    pos: usize,
    /// The first `protected` slots are never overwritten (demonstrations,
    /// [`ReplayBuffer::protect_filled`]): the ring wraps to the slot after them.
    protected: usize,
    obs: Vec<f32>,
    act: Vec<f32>,
    reward: Vec<f32>,
    next_obs: Vec<f32>,
    terminal: Vec<f32>,
}

/// A sampled mini-batch, row-major; reused across updates so sampling does not allocate.
#[derive(Clone, Debug, Default)]
pub struct Batch {
    pub size: usize,
    pub obs: Vec<f32>,
    pub act: Vec<f32>,
    pub reward: Vec<f32>,
    pub next_obs: Vec<f32>,
    pub terminal: Vec<f32>,
    /// 1 where the row is a protected transition (a demonstration), else 0.
    pub demo: Vec<f32>,
}

impl Batch {
    /// A batch of `size` rows for the given dimensions.
    pub fn new(size: usize, obs_dim: usize, act_dim: usize) -> Batch {
        Batch {
            size,
            obs: vec![0.0; size * obs_dim],
            act: vec![0.0; size * act_dim],
            reward: vec![0.0; size],
            next_obs: vec![0.0; size * obs_dim],
            terminal: vec![0.0; size],
            demo: vec![0.0; size],
        }
    }
}

impl ReplayBuffer {
    /// Checkpoint names of the stored arrays, in [`ReplayBuffer::arrays`] order.
    pub const ARRAY_NAMES: [&'static str; 5] =
        ["replay.obs", "replay.act", "replay.reward", "replay.next_obs", "replay.terminal"];

    /// An empty buffer of `capacity >= 1` transitions.
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Result<ReplayBuffer> {
        if capacity == 0 {
            return Err(Error::config("agent.buffer_size", 0, "an integer >= 1"));
        }
        if capacity.checked_mul(obs_dim.max(act_dim).max(1)).and_then(|n| n.checked_mul(4)).is_none() {
            return Err(Error::config(
                "agent.buffer_size",
                capacity,
                format!("a capacity whose arrays ({obs_dim} observation values a transition) fit in memory"),
            ));
        }
        Ok(ReplayBuffer {
            capacity,
            obs_dim,
            act_dim,
            len: 0,
            pos: 0,
            protected: 0,
            obs: vec![0.0; capacity * obs_dim],
            act: vec![0.0; capacity * act_dim],
            reward: vec![0.0; capacity],
            next_obs: vec![0.0; capacity * obs_dim],
            terminal: vec![0.0; capacity],
        })
    }

    /// Store one transition, overwriting the oldest once full.
    #[inline]
    pub fn push(&mut self, obs: &[f32], act: &[f32], reward: f64, next_obs: &[f32], terminal: bool) {
        let (i, od, ad) = (self.pos, self.obs_dim, self.act_dim);
        self.obs[i * od..(i + 1) * od].copy_from_slice(obs);
        self.act[i * ad..(i + 1) * ad].copy_from_slice(act);
        self.reward[i] = reward as f32;
        self.next_obs[i * od..(i + 1) * od].copy_from_slice(next_obs);
        self.terminal[i] = f32::from(u8::from(terminal));
        self.pos = if self.pos + 1 == self.capacity { self.protected } else { self.pos + 1 };
        self.len = (self.len + 1).min(self.capacity);
    }

    /// Fill `batch` with `batch.size` transitions drawn uniformly with replacement.
    /// The buffer must not be empty.
    pub fn sample_into(&self, rng: &mut Rng, batch: &mut Batch) {
        assert!(self.len > 0, "sampling an empty replay buffer");
        let (od, ad) = (self.obs_dim, self.act_dim);
        for b in 0..batch.size {
            let i = rng.below(self.len as u64) as usize;
            copy_row(&mut batch.obs[b * od..(b + 1) * od], &self.obs[i * od..(i + 1) * od]);
            copy_row(&mut batch.act[b * ad..(b + 1) * ad], &self.act[i * ad..(i + 1) * ad]);
            batch.reward[b] = self.reward[i];
            copy_row(&mut batch.next_obs[b * od..(b + 1) * od], &self.next_obs[i * od..(i + 1) * od]);
            batch.terminal[b] = self.terminal[i];
            batch.demo[b] = f32::from(u8::from(i < self.protected));
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn capacity(&self) -> usize {
        self.capacity
    }
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }
    /// The write position (next slot), for checkpoints.
    pub fn position(&self) -> usize {
        self.pos
    }
    /// Slots never overwritten ([`ReplayBuffer::protect_filled`]).
    pub fn protected(&self) -> usize {
        self.protected
    }

    /// Keep every transition stored so far for good (the demonstrations): once full, the ring
    /// overwrites only the slots after them. Errors: the buffer has wrapped already, or they
    /// leave no room (`agent.buffer_size` must exceed them).
    pub fn protect_filled(&mut self) -> Result<()> {
        self.set_protected(self.len)
    }

    /// Restore the protected count of a checkpoint (after [`ReplayBuffer::restore`]).
    pub fn set_protected(&mut self, n: usize) -> Result<()> {
        if n >= self.capacity {
            return Err(Error::config(
                "agent.buffer_size",
                self.capacity,
                format!("more transitions than the {n} kept for good (the demonstrations)"),
            ));
        }
        if n > self.len || (self.len == self.capacity && self.pos < n) {
            return Err(Error::InvalidInput(format!(
                "replay buffer state: {n} protected transitions do not fit length {}, position {}",
                self.len, self.pos
            )));
        }
        self.protected = n;
        Ok(())
    }

    /// The stored arrays in `[obs, act, reward, next_obs, terminal]` order, first `len` rows
    /// only when not yet wrapped (for checkpoints).
    pub fn arrays(&self) -> [(&'static str, &[f32]); 5] {
        let n = self.len;
        let [o, a, rw, no, t] = Self::ARRAY_NAMES;
        [
            (o, &self.obs[..n * self.obs_dim]),
            (a, &self.act[..n * self.act_dim]),
            (rw, &self.reward[..n]),
            (no, &self.next_obs[..n * self.obs_dim]),
            (t, &self.terminal[..n]),
        ]
    }

    /// Restore the contents saved by [`ReplayBuffer::arrays`] with `len` rows and write position
    /// `pos`. Errors if the shapes do not match this buffer.
    pub fn restore(&mut self, len: usize, pos: usize, arrays: [&[f32]; 5]) -> Result<()> {
        if len > self.capacity || pos >= self.capacity.max(1) || (len < self.capacity && pos != len) {
            return Err(Error::InvalidInput(format!(
                "replay buffer state len {len}, position {pos} does not fit capacity {}",
                self.capacity
            )));
        }
        let widths = [self.obs_dim, self.act_dim, 1, self.obs_dim, 1];
        for (k, (a, w)) in arrays.iter().zip(widths).enumerate() {
            if a.len() != len * w {
                return Err(Error::InvalidInput(format!(
                    "replay array {} has {} values, expected {len} x {w}",
                    self.arrays()[k].0,
                    a.len()
                )));
            }
        }
        self.len = len;
        self.pos = pos;
        self.obs[..arrays[0].len()].copy_from_slice(arrays[0]);
        self.act[..arrays[1].len()].copy_from_slice(arrays[1]);
        self.reward[..len].copy_from_slice(arrays[2]);
        self.next_obs[..arrays[3].len()].copy_from_slice(arrays[3]);
        self.terminal[..len].copy_from_slice(arrays[4]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(cap: usize, n: usize) -> ReplayBuffer {
        let mut b = ReplayBuffer::new(cap, 2, 1).unwrap();
        for k in 0..n {
            let x = k as f32;
            b.push(&[x, x + 0.5], &[-x], k as f64, &[x + 1.0, x + 1.5], k % 3 == 0);
        }
        b
    }

    #[test]
    fn samples_are_stored_transitions() {
        let b = filled(100, 40);
        let mut batch = Batch::new(64, 2, 1);
        let mut rng = Rng::new(1);
        b.sample_into(&mut rng, &mut batch);
        for r in 0..64 {
            let x = batch.obs[2 * r];
            assert_eq!(batch.obs[2 * r + 1], x + 0.5);
            assert_eq!(batch.act[r], -x);
            assert_eq!(batch.reward[r], x);
            assert_eq!(batch.next_obs[2 * r], x + 1.0);
            assert_eq!(batch.terminal[r], f32::from(u8::from((x as usize).is_multiple_of(3))));
            assert!(x < 40.0);
        }
    }

    #[test]
    fn ring_overwrites_the_oldest() {
        let b = filled(10, 25);
        assert_eq!(b.len(), 10);
        assert_eq!(b.position(), 5);
        let mut batch = Batch::new(500, 2, 1);
        b.sample_into(&mut Rng::new(2), &mut batch);
        let mut seen = [false; 25];
        for r in 0..500 {
            seen[batch.reward[r] as usize] = true;
        }
        assert!(seen[..15].iter().all(|s| !s), "old transitions were overwritten");
        assert!(seen[15..].iter().all(|s| *s), "every live transition is sampled");
    }

    #[test]
    fn restore_round_trips_and_checks_shapes() {
        let a = filled(50, 30);
        let mut b = ReplayBuffer::new(50, 2, 1).unwrap();
        let arr = a.arrays();
        b.restore(a.len(), a.position(), [arr[0].1, arr[1].1, arr[2].1, arr[3].1, arr[4].1]).unwrap();
        assert_eq!(a, b);
        let mut c = ReplayBuffer::new(50, 3, 1).unwrap();
        assert!(c
            .restore(a.len(), a.position(), [arr[0].1, arr[1].1, arr[2].1, arr[3].1, arr[4].1])
            .is_err());
        assert!(ReplayBuffer::new(0, 2, 1).is_err());
    }

    #[test]
    fn protected_transitions_are_never_overwritten_and_sampled_as_demonstrations() {
        let mut b = filled(5, 2);
        b.protect_filled().unwrap();
        for k in 2..9 {
            let x = k as f32;
            b.push(&[x, x + 0.5], &[-x], k as f64, &[x + 1.0, x + 1.5], false);
        }
        // Slots 0-1 keep transitions 0-1; slots 2-4 take 2-8 in turn (8 in slot 2 last).
        assert_eq!(b.arrays()[2].1, [0.0, 1.0, 8.0, 6.0, 7.0]);
        assert_eq!((b.len(), b.position(), b.protected()), (5, 3, 2));
        let mut batch = Batch::new(64, 2, 1);
        b.sample_into(&mut Rng::new(3), &mut batch);
        for (r, d) in batch.reward.iter().zip(&batch.demo) {
            assert_eq!(*d == 1.0, *r < 2.0, "reward {r} demo {d}");
        }
        assert!(batch.demo.contains(&1.0) && batch.demo.contains(&0.0));
        // A restore takes the count back; counts that do not fit are refused.
        let mut c = ReplayBuffer::new(5, 2, 1).unwrap();
        let a = b.arrays();
        c.restore(5, 3, [a[0].1, a[1].1, a[2].1, a[3].1, a[4].1]).unwrap();
        c.set_protected(2).unwrap();
        assert_eq!(c, b);
        assert!(c.set_protected(4).is_err(), "position 3 is inside 4 protected slots");
        let e = filled(3, 3).protect_filled().unwrap_err().to_string();
        assert!(e.contains("`agent.buffer_size`"), "{e}");
    }
}
