//! Multichannel sampled signals in time-major layout.

use crate::error::LtiError;

/// A sampled multichannel signal of `len` samples and `channels` channels.
///
/// Storage is time-major (row-major): the value of channel `c` at time `k` lives at
/// index `k * channels + c` of [`Signal::as_slice`]. This is exactly the stacked layout
/// the [`LinearSystem`](crate::LinearSystem) operators work on.
///
/// The length is stored explicitly, so a signal with zero channels (for example the
/// input of a system without inputs) still knows how many samples it spans.
#[derive(Clone, Debug, PartialEq)]
pub struct Signal {
    len: usize,
    channels: usize,
    data: Vec<f64>,
}

impl Signal {
    /// Wraps time-major data (`data[k * channels + c]`).
    ///
    /// `data.len()` must be a multiple of `channels`. With `channels == 0` only empty data
    /// is accepted and the signal has length 0; use [`Signal::zeros`]`(len, 0)` for a
    /// zero-channel signal with a nonzero length.
    ///
    /// ```
    /// use structid_lti::Signal;
    /// // two channels, three samples
    /// let s = Signal::new(2, vec![1.0, 10.0, 2.0, 20.0, 3.0, 30.0]).unwrap();
    /// assert_eq!(s.len(), 3);
    /// assert_eq!(s.sample(1), &[2.0, 20.0]);
    /// assert_eq!(s.channel(1), vec![10.0, 20.0, 30.0]);
    /// assert!(Signal::new(2, vec![1.0, 2.0, 3.0]).is_err());
    /// ```
    pub fn new(channels: usize, data: Vec<f64>) -> Result<Self, LtiError> {
        if channels == 0 {
            if !data.is_empty() {
                return Err(LtiError::dims(
                    "signal data with zero channels",
                    "no data",
                    format!("{} values", data.len()),
                ));
            }
            return Ok(Signal {
                len: 0,
                channels: 0,
                data,
            });
        }
        if !data.len().is_multiple_of(channels) {
            return Err(LtiError::dims(
                "signal data length",
                format!("a multiple of the channel count {channels}"),
                data.len(),
            ));
        }
        Ok(Signal {
            len: data.len() / channels,
            channels,
            data,
        })
    }

    /// An all-zero signal with `len` samples and `channels` channels.
    ///
    /// ```
    /// use structid_lti::Signal;
    /// let s = Signal::zeros(5, 0);
    /// assert_eq!((s.len(), s.channels()), (5, 0));
    /// ```
    pub fn zeros(len: usize, channels: usize) -> Self {
        Signal {
            len,
            channels,
            data: vec![0.0; len * channels],
        }
    }

    /// Builds a signal from per-channel time series (`columns[c][k]`); all channels must
    /// have the same length. An empty slice gives the empty zero-channel signal.
    ///
    /// ```
    /// use structid_lti::Signal;
    /// let s = Signal::from_channels(&[vec![1.0, 2.0], vec![3.0, 4.0]]).unwrap();
    /// assert_eq!(s.as_slice(), &[1.0, 3.0, 2.0, 4.0]);
    /// ```
    pub fn from_channels(columns: &[Vec<f64>]) -> Result<Self, LtiError> {
        let channels = columns.len();
        let len = columns.first().map_or(0, Vec::len);
        for (c, col) in columns.iter().enumerate() {
            if col.len() != len {
                return Err(LtiError::dims(
                    format!("length of channel {c}"),
                    format!("{len} samples (as channel 0)"),
                    format!("{} samples", col.len()),
                ));
            }
        }
        let mut data = Vec::with_capacity(len * channels);
        for k in 0..len {
            for col in columns {
                data.push(col[k]);
            }
        }
        Ok(Signal {
            len,
            channels,
            data,
        })
    }

    /// Builds a signal from `f(k, c)` (time `k`, channel `c`).
    ///
    /// ```
    /// use structid_lti::Signal;
    /// let s = Signal::from_fn(3, 2, |k, c| (10 * c + k) as f64);
    /// assert_eq!(s.get(2, 1), 12.0);
    /// ```
    pub fn from_fn(len: usize, channels: usize, mut f: impl FnMut(usize, usize) -> f64) -> Self {
        let mut data = Vec::with_capacity(len * channels);
        for k in 0..len {
            for c in 0..channels {
                data.push(f(k, c));
            }
        }
        Signal {
            len,
            channels,
            data,
        }
    }

    /// Number of samples `L`.
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` when the signal has no samples.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of channels.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The `channels` values at time `k`. Panics if `k >= len`.
    pub fn sample(&self, k: usize) -> &[f64] {
        assert!(
            k < self.len,
            "sample index {k} out of range (len {})",
            self.len
        );
        &self.data[k * self.channels..(k + 1) * self.channels]
    }

    /// Mutable access to the values at time `k`. Panics if `k >= len`.
    pub fn sample_mut(&mut self, k: usize) -> &mut [f64] {
        assert!(
            k < self.len,
            "sample index {k} out of range (len {})",
            self.len
        );
        &mut self.data[k * self.channels..(k + 1) * self.channels]
    }

    /// A copy of channel `c` over time. Panics if `c >= channels`.
    pub fn channel(&self, c: usize) -> Vec<f64> {
        assert!(
            c < self.channels,
            "channel index {c} out of range ({} channels)",
            self.channels
        );
        (0..self.len)
            .map(|k| self.data[k * self.channels + c])
            .collect()
    }

    /// The time-major data, length `len * channels`, index `k * channels + c`.
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }

    /// Mutable time-major data.
    pub fn as_mut_slice(&mut self) -> &mut [f64] {
        &mut self.data
    }

    /// Consumes the signal and returns its time-major data.
    pub fn into_vec(self) -> Vec<f64> {
        self.data
    }

    /// Value of channel `c` at time `k`. Panics when out of range.
    pub fn get(&self, k: usize, c: usize) -> f64 {
        assert!(
            k < self.len && c < self.channels,
            "index ({k}, {c}) out of range for a signal of {} samples x {} channels",
            self.len,
            self.channels
        );
        self.data[k * self.channels + c]
    }

    /// Returns [`LtiError::NonFinite`] for the first NaN or infinite value (in time order);
    /// `what` names the signal in the error message.
    pub fn check_finite(&self, what: &str) -> Result<(), LtiError> {
        match self.data.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(i) => Err(LtiError::NonFinite {
                what: what.to_string(),
                sample: i / self.channels,
                channel: i % self.channels,
                value: self.data[i],
            }),
        }
    }

    /// A new signal made of the channels `idx` (in that order; repetitions allowed).
    ///
    /// The caller guarantees `idx[i] < channels`; an out-of-range index panics.
    pub fn select_channels(&self, idx: &[usize]) -> Signal {
        for &c in idx {
            assert!(
                c < self.channels,
                "channel index {c} out of range ({} channels)",
                self.channels
            );
        }
        Signal::from_fn(self.len, idx.len(), |k, i| {
            self.data[k * self.channels + idx[i]]
        })
    }

    /// The samples in the time range `range` (all channels). Panics if the range is not
    /// within `0..len`.
    pub fn slice(&self, range: std::ops::Range<usize>) -> Signal {
        assert!(
            range.start <= range.end && range.end <= self.len,
            "time range {range:?} out of bounds for a signal of {} samples",
            self.len
        );
        Signal {
            len: range.end - range.start,
            channels: self.channels,
            data: self.data[range.start * self.channels..range.end * self.channels].to_vec(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn construction_and_access() {
        let s = Signal::from_fn(4, 3, |k, c| (k * 10 + c) as f64);
        assert_eq!(s.len(), 4);
        assert_eq!(s.channels(), 3);
        assert_eq!(s.get(2, 1), 21.0);
        assert_eq!(s.channel(2), vec![2.0, 12.0, 22.0, 32.0]);
        let t = Signal::from_channels(&[s.channel(0), s.channel(1), s.channel(2)]).unwrap();
        assert_eq!(s, t);
        let sel = s.select_channels(&[2, 0]);
        assert_eq!(sel.sample(3), &[32.0, 30.0]);
        let sl = s.slice(1..3);
        assert_eq!(sl.len(), 2);
        assert_eq!(sl.sample(0), s.sample(1));
        assert_eq!(Signal::new(3, s.clone().into_vec()).unwrap(), s);
    }

    #[test]
    fn zero_channel_signal_keeps_length() {
        let s = Signal::zeros(7, 0);
        assert_eq!(s.len(), 7);
        assert!(s.sample(3).is_empty());
        assert_eq!(s.slice(2..5).len(), 3);
        assert_eq!(s.select_channels(&[]).len(), 7);
        assert!(Signal::new(0, vec![1.0]).is_err());
        assert!(Signal::new(0, vec![]).unwrap().is_empty());
    }

    #[test]
    fn rejects_ragged_and_nonfinite() {
        assert!(Signal::from_channels(&[vec![1.0], vec![1.0, 2.0]]).is_err());
        let mut s = Signal::zeros(3, 2);
        assert!(s.check_finite("u").is_ok());
        s.sample_mut(2)[1] = f64::NAN;
        match s.check_finite("u") {
            Err(LtiError::NonFinite {
                sample, channel, ..
            }) => assert_eq!((sample, channel), (2, 1)),
            other => panic!("unexpected {other:?}"),
        }
    }
}
