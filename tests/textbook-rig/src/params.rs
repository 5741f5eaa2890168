//! The rig's true parameters: every key of the workbench's parameter file (docs/formats.md,
//! "Keys"), plus the rig-only settings of the bench (current limit, current loop, ambient).

use crate::RigError;

/// The four documented forms of the Jiles–Atherton equations (`[ja] variant`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JaVariant {
    /// `bulk`: irreversible change in the effective field (Venkataraman 1999; Dapino et al. 2000).
    Bulk,
    /// `ja1986`: dM_irr/dH with the δ_M gate (Jiles & Atherton 1986).
    Ja1986,
    /// `szewczyk`: total-magnetization form with the δ_M gate on M_an − M.
    Szewczyk,
    /// `ja1986-ungated`: the total-magnetization form as printed, slope clipped at 0.
    Ja1986Ungated,
}

impl JaVariant {
    /// The parameter-file word.
    pub fn name(self) -> &'static str {
        match self {
            JaVariant::Bulk => "bulk",
            JaVariant::Ja1986 => "ja1986",
            JaVariant::Szewczyk => "szewczyk",
            JaVariant::Ja1986Ungated => "ja1986-ungated",
        }
    }
    /// All four forms.
    pub const ALL: [JaVariant; 4] =
        [JaVariant::Bulk, JaVariant::Ja1986, JaVariant::Szewczyk, JaVariant::Ja1986Ungated];
    /// From the parameter-file word.
    pub fn parse(s: &str) -> Result<JaVariant, RigError> {
        JaVariant::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| RigError::BadParameter(format!("ja.variant: unknown form `{s}`")))
    }
}

/// `[amp]`: first-order amplifier i = g u/(τ s + 1).
#[derive(Clone, Debug, PartialEq)]
pub struct AmpParams {
    /// g [A/V].
    pub gain_a_per_v: f64,
    /// τ [s].
    pub tau_s: f64,
}

/// `[amp_second_order]`: k_U (A s + 1)/(B s² + C s + 1), used instead of `[amp]` when present.
#[derive(Clone, Debug, PartialEq)]
pub struct AmpSecondOrder {
    /// k_U [A/V].
    pub k_u: f64,
    /// A [s].
    pub a_s: f64,
    /// B [s²].
    pub b_s2: f64,
    /// C [s].
    pub c_s: f64,
}

/// `[coil]`: H = turns_per_m · i + bias.
#[derive(Clone, Debug, PartialEq)]
pub struct CoilParams {
    /// Field per ampere [1/m].
    pub turns_per_m: f64,
    /// Bias field [A/m].
    pub bias_a_per_m: f64,
}

/// `[linear]`: M = a + b H.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearParams {
    /// a [A/m].
    pub offset_a_per_m: f64,
    /// b.
    pub susceptibility: f64,
}

/// `[anhysteretic]`: M = M_s L(H/a).
#[derive(Clone, Debug, PartialEq)]
pub struct AnhystereticParams {
    /// M_s [A/m].
    pub ms_a_per_m: f64,
    /// a [A/m].
    pub a_a_per_m: f64,
}

/// `[ja]`: Jiles–Atherton coefficients and form.
#[derive(Clone, Debug, PartialEq)]
pub struct JaParams {
    /// M_s [A/m].
    pub ms_a_per_m: f64,
    /// a [A/m].
    pub a_a_per_m: f64,
    /// α.
    pub alpha: f64,
    /// k [A/m].
    pub k_a_per_m: f64,
    /// c.
    pub c: f64,
    /// The form of the equations.
    pub variant: JaVariant,
}

/// `[preisach]`: Lorentzian relay density.
#[derive(Clone, Debug, PartialEq)]
pub struct PreisachParams {
    /// Output at positive saturation [A/m].
    pub ms_a_per_m: f64,
    /// h_c [A/m].
    pub coercive_a_per_m: f64,
    /// σ [A/m].
    pub spread_a_per_m: f64,
    /// σ_u [A/m]; `None`: the factorised one-width density.
    pub interaction_spread_a_per_m: Option<f64>,
    /// ρ.
    pub reversible_fraction: f64,
    /// h_r [A/m]; `None`: the interaction spread (else the spread).
    pub reversible_field_a_per_m: Option<f64>,
    /// ±H_max [A/m].
    pub h_max_a_per_m: f64,
}

impl PreisachParams {
    /// The reversible part's field scale in effect.
    pub fn reversible_field(&self) -> f64 {
        self.reversible_field_a_per_m.or(self.interaction_spread_a_per_m).unwrap_or(self.spread_a_per_m)
    }
}

/// `[magnetostriction.preload]` (002 eq. 3).
#[derive(Clone, Debug, PartialEq)]
pub struct Preload {
    /// F [N].
    pub force_n: f64,
    /// F_s [N].
    pub optimal_force_n: f64,
    /// F_max [N].
    pub max_force_n: f64,
}

impl Preload {
    /// The strain factor (1 + ½ tanh(2F/F_s)), times (1 − (F − F_s)/F_max) above F_s.
    pub fn factor(&self) -> f64 {
        let base = 1.0 + 0.5 * (2.0 * self.force_n / self.optimal_force_n).tanh();
        if self.force_n <= self.optimal_force_n {
            base
        } else {
            (1.0 - (self.force_n - self.optimal_force_n) / self.max_force_n) * base
        }
    }
}

/// `[magnetostriction]`: λ = (3/2)(λ_s/M_s²)(M² − M_b²) (× the preload factor).
#[derive(Clone, Debug, PartialEq)]
pub struct MagnetostrictionParams {
    /// λ_s.
    pub lambda_s: f64,
    /// M_s the strain is normalised by [A/m].
    pub ms_a_per_m: f64,
    /// M_b [A/m].
    pub bias_m_a_per_m: f64,
    /// Optional preload table.
    pub preload: Option<Preload>,
}

/// `[mech]`: unit-gain mass–spring–damper.
#[derive(Clone, Debug, PartialEq)]
pub struct MechParams {
    /// f_n [Hz].
    pub natural_frequency_hz: f64,
    /// ζ.
    pub damping_ratio: f64,
}

/// `[aftereffect]`: M_obs = (1 − w) M + w M_slow, M_slow' = (M − M_slow)/τ.
#[derive(Clone, Debug, PartialEq)]
pub struct AftereffectParams {
    /// w.
    pub fraction: f64,
    /// τ [s].
    pub tau_s: f64,
}

/// `[thermal]`: coil heating and the rod's expansion.
#[derive(Clone, Debug, PartialEq)]
pub struct ThermalParams {
    /// R [Ω].
    pub coil_resistance_ohm: f64,
    /// R_th [°C/W].
    pub thermal_resistance_c_per_w: f64,
    /// Coil thermal time constant [s].
    pub tau_s: f64,
    /// Expanding length [m].
    pub rod_length_m: f64,
    /// α_T [1/°C].
    pub expansion_per_c: f64,
    /// Rod lag behind the coil [s]; 0: none.
    pub rod_tau_s: f64,
}

/// Settings of the bench that are not model parameters (not written to the gma file).
#[derive(Clone, Debug, PartialEq)]
pub struct RigParams {
    /// Current limit of the amplifier / current source [A] (the demand is clamped).
    pub current_limit_a: f64,
    /// Current-mode loop time constant [s]; 0: an ideal current source.
    pub current_loop_tau_s: f64,
    /// Ambient temperature the coil heats from [°C].
    pub ambient_c: f64,
}

/// Every parameter of the documented parameter file, f64, plus the bench settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    /// Sample period [s] (the delay counts periods of it).
    pub dt_s: f64,
    /// Eddy-current lag [s].
    pub eddy_tau_s: f64,
    /// Active rod length [m].
    pub rod_length_m: f64,
    /// Sensor delay in periods of `dt_s` (fractional allowed).
    pub delay_samples: f64,
    /// `[amp]`.
    pub amp: AmpParams,
    /// `[amp_second_order]`.
    pub amp_second_order: Option<AmpSecondOrder>,
    /// `[coil]`.
    pub coil: CoilParams,
    /// `[linear]`.
    pub linear: LinearParams,
    /// `[anhysteretic]`.
    pub anhysteretic: AnhystereticParams,
    /// `[ja]`.
    pub ja: JaParams,
    /// `[preisach]`.
    pub preisach: PreisachParams,
    /// `[magnetostriction]` (with `[magnetostriction.preload]`).
    pub magnetostriction: MagnetostrictionParams,
    /// `[mech]`.
    pub mech: MechParams,
    /// `[aftereffect]`.
    pub aftereffect: AftereffectParams,
    /// `[thermal]`.
    pub thermal: ThermalParams,
    /// Bench settings (not in the gma file).
    pub rig: RigParams,
}

impl Default for Params {
    fn default() -> Params {
        Params::terfenol()
    }
}

fn f(x: f64) -> String {
    format!("{x:?}")
}

impl Params {
    /// The rig's own Terfenol-D actuator (values chosen from the papers; see the README).
    pub fn terfenol() -> Params {
        Params {
            dt_s: 1e-4,
            eddy_tau_s: 1.0e-4,
            rod_length_m: 0.08,
            delay_samples: 2.5,
            amp: AmpParams { gain_a_per_v: 1.5, tau_s: 1.5e-4 },
            amp_second_order: None,
            coil: CoilParams { turns_per_m: 1.0e4, bias_a_per_m: 8000.0 },
            linear: LinearParams { offset_a_per_m: 6.0e4, susceptibility: 25.0 },
            anhysteretic: AnhystereticParams { ms_a_per_m: 7.65e5, a_a_per_m: 8000.0 },
            ja: JaParams {
                ms_a_per_m: 7.65e5,
                a_a_per_m: 7000.0,
                alpha: -0.01,
                k_a_per_m: 3500.0,
                c: 0.18,
                variant: JaVariant::Bulk,
            },
            preisach: PreisachParams {
                ms_a_per_m: 7.65e5,
                coercive_a_per_m: 3000.0,
                spread_a_per_m: 4000.0,
                interaction_spread_a_per_m: Some(8000.0),
                reversible_fraction: 0.2,
                reversible_field_a_per_m: Some(12000.0),
                h_max_a_per_m: 6.0e4,
            },
            magnetostriction: MagnetostrictionParams {
                lambda_s: 1.1e-3,
                ms_a_per_m: 7.65e5,
                bias_m_a_per_m: 2.5e5,
                preload: None,
            },
            mech: MechParams { natural_frequency_hz: 1700.0, damping_ratio: 0.45 },
            aftereffect: AftereffectParams { fraction: 0.08, tau_s: 0.05 },
            thermal: ThermalParams {
                coil_resistance_ohm: 6.0,
                thermal_resistance_c_per_w: 2.0,
                tau_s: 20.0,
                rod_length_m: 0.08,
                expansion_per_c: 12.9e-6,
                rod_tau_s: 5.0,
            },
            rig: RigParams { current_limit_a: 3.9, current_loop_tau_s: 20e-6, ambient_c: 25.0 },
        }
    }

    /// The complete gma parameter file (every table and key, `[ja] variant` included).
    pub fn to_gma_toml(&self) -> String {
        let mut s = String::new();
        s.push_str("# textrig (textbook rig) TRUE parameters: SIMULATED physics, every table written\n");
        s.push_str(&format!("dt_s = {}\n", f(self.dt_s)));
        s.push_str(&format!("eddy_tau_s = {}\n", f(self.eddy_tau_s)));
        s.push_str(&format!("rod_length_m = {}\n", f(self.rod_length_m)));
        s.push_str(&format!("delay_samples = {}\n", f(self.delay_samples)));
        s.push_str(&format!(
            "\n[amp]\ngain_a_per_v = {}\ntau_s = {}\n",
            f(self.amp.gain_a_per_v),
            f(self.amp.tau_s)
        ));
        if let Some(a) = &self.amp_second_order {
            s.push_str(&format!(
                "\n[amp_second_order]\nk_u = {}\na_s = {}\nb_s2 = {}\nc_s = {}\n",
                f(a.k_u),
                f(a.a_s),
                f(a.b_s2),
                f(a.c_s)
            ));
        }
        s.push_str(&format!(
            "\n[coil]\nturns_per_m = {}\nbias_a_per_m = {}\n",
            f(self.coil.turns_per_m),
            f(self.coil.bias_a_per_m)
        ));
        s.push_str(&format!(
            "\n[linear]\noffset_a_per_m = {}\nsusceptibility = {}\n",
            f(self.linear.offset_a_per_m),
            f(self.linear.susceptibility)
        ));
        s.push_str(&format!(
            "\n[anhysteretic]\nms_a_per_m = {}\na_a_per_m = {}\n",
            f(self.anhysteretic.ms_a_per_m),
            f(self.anhysteretic.a_a_per_m)
        ));
        let j = &self.ja;
        s.push_str(&format!(
            "\n[ja]\nms_a_per_m = {}\na_a_per_m = {}\nalpha = {}\nk_a_per_m = {}\nc = {}\nvariant = \"{}\"\n",
            f(j.ms_a_per_m),
            f(j.a_a_per_m),
            f(j.alpha),
            f(j.k_a_per_m),
            f(j.c),
            j.variant.name()
        ));
        let p = &self.preisach;
        s.push_str(&format!(
            "\n[preisach]\nms_a_per_m = {}\ncoercive_a_per_m = {}\nspread_a_per_m = {}\n",
            f(p.ms_a_per_m),
            f(p.coercive_a_per_m),
            f(p.spread_a_per_m)
        ));
        if let Some(v) = p.interaction_spread_a_per_m {
            s.push_str(&format!("interaction_spread_a_per_m = {}\n", f(v)));
        }
        s.push_str(&format!("reversible_fraction = {}\n", f(p.reversible_fraction)));
        if let Some(v) = p.reversible_field_a_per_m {
            s.push_str(&format!("reversible_field_a_per_m = {}\n", f(v)));
        }
        s.push_str(&format!("h_max_a_per_m = {}\n", f(p.h_max_a_per_m)));
        let m = &self.magnetostriction;
        s.push_str(&format!(
            "\n[magnetostriction]\nlambda_s = {}\nms_a_per_m = {}\nbias_m_a_per_m = {}\n",
            f(m.lambda_s),
            f(m.ms_a_per_m),
            f(m.bias_m_a_per_m)
        ));
        if let Some(pl) = &m.preload {
            s.push_str(&format!(
                "\n[magnetostriction.preload]\nforce_n = {}\noptimal_force_n = {}\nmax_force_n = {}\n",
                f(pl.force_n),
                f(pl.optimal_force_n),
                f(pl.max_force_n)
            ));
        }
        s.push_str(&format!(
            "\n[mech]\nnatural_frequency_hz = {}\ndamping_ratio = {}\n",
            f(self.mech.natural_frequency_hz),
            f(self.mech.damping_ratio)
        ));
        s.push_str(&format!(
            "\n[aftereffect]\nfraction = {}\ntau_s = {}\n",
            f(self.aftereffect.fraction),
            f(self.aftereffect.tau_s)
        ));
        let t = &self.thermal;
        s.push_str(&format!(
            "\n[thermal]\ncoil_resistance_ohm = {}\nthermal_resistance_c_per_w = {}\ntau_s = {}\nrod_length_m = {}\nexpansion_per_c = {}\nrod_tau_s = {}\n",
            f(t.coil_resistance_ohm),
            f(t.thermal_resistance_c_per_w),
            f(t.tau_s),
            f(t.rod_length_m),
            f(t.expansion_per_c),
            f(t.rod_tau_s)
        ));
        s
    }

    /// Override these parameters with the keys a gma parameter file gives (keys it leaves out
    /// keep their values; an unknown key or table is refused, naming it).
    pub fn apply_gma_toml(&mut self, text: &str) -> Result<(), RigError> {
        let table: toml::Table =
            text.parse().map_err(|e| RigError::BadParameter(format!("parameter file: {e}")))?;
        let num = |k: &str, v: &toml::Value| -> Result<f64, RigError> {
            match v {
                toml::Value::Float(x) => Ok(*x),
                toml::Value::Integer(i) => Ok(*i as f64),
                _ => Err(RigError::BadParameter(format!("`{k}`: not a number"))),
            }
        };
        let unknown = |k: &str| RigError::BadParameter(format!("unknown parameter `{k}`"));
        for (key, val) in &table {
            match key.as_str() {
                "dt_s" => self.dt_s = num(key, val)?,
                "eddy_tau_s" => self.eddy_tau_s = num(key, val)?,
                "rod_length_m" => self.rod_length_m = num(key, val)?,
                "delay_samples" => self.delay_samples = num(key, val)?,
                _ => {
                    let sub = val.as_table().ok_or_else(|| unknown(key))?;
                    if key == "amp_second_order" && self.amp_second_order.is_none() {
                        self.amp_second_order =
                            Some(AmpSecondOrder { k_u: 1.0, a_s: 0.0, b_s2: 1e-8, c_s: 0.0 });
                    }
                    for (k, v) in sub {
                        let full = format!("{key}.{k}");
                        if key == "magnetostriction" && k == "preload" {
                            let pt = v.as_table().ok_or_else(|| unknown(&full))?;
                            let mut pl = self.magnetostriction.preload.clone().unwrap_or(Preload {
                                force_n: 0.0,
                                optimal_force_n: 1.0,
                                max_force_n: 1.0,
                            });
                            for (pk, pv) in pt {
                                let fk = format!("{full}.{pk}");
                                let x = num(&fk, pv)?;
                                match pk.as_str() {
                                    "force_n" => pl.force_n = x,
                                    "optimal_force_n" => pl.optimal_force_n = x,
                                    "max_force_n" => pl.max_force_n = x,
                                    _ => return Err(unknown(&fk)),
                                }
                            }
                            self.magnetostriction.preload = Some(pl);
                            continue;
                        }
                        if key == "ja" && k == "variant" {
                            let s = v
                                .as_str()
                                .ok_or_else(|| RigError::BadParameter("ja.variant: not a string".into()))?;
                            self.ja.variant = JaVariant::parse(s)?;
                            continue;
                        }
                        let x = num(&full, v)?;
                        let slot: &mut f64 = match (key.as_str(), k.as_str()) {
                            ("amp", "gain_a_per_v") => &mut self.amp.gain_a_per_v,
                            ("amp", "tau_s") => &mut self.amp.tau_s,
                            ("amp_second_order", kk) => {
                                let a = self.amp_second_order.as_mut().expect("set above");
                                match kk {
                                    "k_u" => &mut a.k_u,
                                    "a_s" => &mut a.a_s,
                                    "b_s2" => &mut a.b_s2,
                                    "c_s" => &mut a.c_s,
                                    _ => return Err(unknown(&full)),
                                }
                            }
                            ("coil", "turns_per_m") => &mut self.coil.turns_per_m,
                            ("coil", "bias_a_per_m") => &mut self.coil.bias_a_per_m,
                            ("linear", "offset_a_per_m") => &mut self.linear.offset_a_per_m,
                            ("linear", "susceptibility") => &mut self.linear.susceptibility,
                            ("anhysteretic", "ms_a_per_m") => &mut self.anhysteretic.ms_a_per_m,
                            ("anhysteretic", "a_a_per_m") => &mut self.anhysteretic.a_a_per_m,
                            ("ja", "ms_a_per_m") => &mut self.ja.ms_a_per_m,
                            ("ja", "a_a_per_m") => &mut self.ja.a_a_per_m,
                            ("ja", "alpha") => &mut self.ja.alpha,
                            ("ja", "k_a_per_m") => &mut self.ja.k_a_per_m,
                            ("ja", "c") => &mut self.ja.c,
                            ("preisach", "ms_a_per_m") => &mut self.preisach.ms_a_per_m,
                            ("preisach", "coercive_a_per_m") => &mut self.preisach.coercive_a_per_m,
                            ("preisach", "spread_a_per_m") => &mut self.preisach.spread_a_per_m,
                            ("preisach", "interaction_spread_a_per_m") => {
                                self.preisach.interaction_spread_a_per_m = Some(x);
                                continue;
                            }
                            ("preisach", "reversible_fraction") => &mut self.preisach.reversible_fraction,
                            ("preisach", "reversible_field_a_per_m") => {
                                self.preisach.reversible_field_a_per_m = Some(x);
                                continue;
                            }
                            ("preisach", "h_max_a_per_m") => &mut self.preisach.h_max_a_per_m,
                            ("magnetostriction", "lambda_s") => &mut self.magnetostriction.lambda_s,
                            ("magnetostriction", "ms_a_per_m") => &mut self.magnetostriction.ms_a_per_m,
                            ("magnetostriction", "bias_m_a_per_m") => {
                                &mut self.magnetostriction.bias_m_a_per_m
                            }
                            ("mech", "natural_frequency_hz") => &mut self.mech.natural_frequency_hz,
                            ("mech", "damping_ratio") => &mut self.mech.damping_ratio,
                            ("aftereffect", "fraction") => &mut self.aftereffect.fraction,
                            ("aftereffect", "tau_s") => &mut self.aftereffect.tau_s,
                            ("thermal", "coil_resistance_ohm") => &mut self.thermal.coil_resistance_ohm,
                            ("thermal", "thermal_resistance_c_per_w") => {
                                &mut self.thermal.thermal_resistance_c_per_w
                            }
                            ("thermal", "tau_s") => &mut self.thermal.tau_s,
                            ("thermal", "rod_length_m") => &mut self.thermal.rod_length_m,
                            ("thermal", "expansion_per_c") => &mut self.thermal.expansion_per_c,
                            ("thermal", "rod_tau_s") => &mut self.thermal.rod_tau_s,
                            _ => return Err(unknown(&full)),
                        };
                        *slot = x;
                    }
                }
            }
        }
        Ok(())
    }
}
