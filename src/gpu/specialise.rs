//! Specialisation on the host, before the driver sees a kernel.
//!
//! A kernel's pipeline-overridable constants (`override` in WGSL: the scene's materials, the
//! gate's kind, the method's family, NLOS, statistics, ...) switch whole branches of code on and
//! off. wgpu substitutes their values but hands the driver every branch, with conditions that are
//! now constant; the driver then translates and inlines all of it before its own optimisation
//! removes the dead branches. On CPU Vulkan that translation is most of a render's start-up, and
//! it is paid on every run, even when the driver finds the compiled code in its disk cache.
//!
//! [`specialise`] therefore substitutes the constants itself (naga's `process_overrides`), then
//! replaces every `if` whose condition became constant by the branch it takes (and every `switch`
//! on a constant by its case), and drops the functions no longer called. A condition is constant
//! where it is
//! - a literal or a constant;
//! - `!c`, `a && b` or `a || b` that constant operands decide (naga expressions have no side
//!   effects, so `a && false` is `false` whatever `a`);
//! - the value of a short-circuit operator: WGSL's `a && b` becomes an unnamed `bool` variable
//!   stored once in each branch of `if a`; once one branch is gone, the variable holds the
//!   other's single constant store wherever it is read;
//! - the result of a call to a function whose every `return` returns the same constant (the call
//!   stays; only its result is known), such as `is_plastic` without plastic in the scene.
//!
//! Functions are visited callees first (naga's order), each until nothing more is pruned. The
//! result is the same program, which the driver then translates in a fraction of the time.
//!
//! `GATETRACE_NO_PRUNING=1` in the environment hands the driver the kernels as written instead,
//! with wgpu substituting the constants: renders are bit for bit the same either way
//! (`tests/specialise.rs` checks it), only the start-up differs.

use std::collections::HashMap;

use naga::back::PipelineConstants;
use naga::back::pipeline_constants::process_overrides;
use naga::valid::{Capabilities, ValidationFlags, Validator};
use naga::{
    Arena, BinaryOperator, Block, Expression, Function, Handle, Literal, LocalVariable, Module, Statement, SwitchValue,
    UnaryOperator,
};

use super::kernels::KernelSource;

/// Whether kernels reach the driver pruned ([`specialise`]), unless `GATETRACE_NO_PRUNING=1`.
pub fn pruning() -> bool {
    static PRUNING: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *PRUNING.get_or_init(|| std::env::var_os("GATETRACE_NO_PRUNING").is_none_or(|v| v != "1"))
}

/// The module of `source` with `constants` (overrides the kernel declares, by name) substituted
/// and every branch their values rule out removed. Fails only on a kernel the build script would
/// have refused, or on a constant the kernel does not declare.
pub fn specialise(source: &KernelSource, constants: &[(&str, f64)]) -> Result<Module, String> {
    let what = |e: &dyn std::fmt::Display| format!("kernel `{}`: {e}", source.name);
    let module = naga::front::wgsl::parse_str(source.wgsl).map_err(|e| what(&e.emit_to_string(source.wgsl)))?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::all()).validate(&module).map_err(|e| what(&e))?;
    let values: PipelineConstants = constants.iter().map(|&(k, v)| (k.to_owned(), v)).collect();
    let (module, _) = process_overrides(&module, &info, Some((naga::ShaderStage::Compute, source.name)), &values)
        .map_err(|e| what(&e))?;
    let mut module = module.into_owned();
    let mut returns = HashMap::new();
    let mut functions = std::mem::take(&mut module.functions);
    for (handle, function) in functions.iter_mut() {
        if let Some(value) = prune_function(&module, &returns, function) {
            returns.insert(handle, value);
        }
    }
    module.functions = functions;
    let mut entry_points = std::mem::take(&mut module.entry_points);
    for entry in entry_points.iter_mut() {
        prune_function(&module, &returns, &mut entry.function);
    }
    module.entry_points = entry_points;
    // Every use of an override is a constant now; what is left are their declarations.
    module.overrides = Arena::new();
    naga::compact::compact(&mut module, naga::compact::KeepUnused::No);
    Ok(module)
}

/// What is known inside one function: the module's constants, the constant results of the
/// functions it may call, and its variables that hold one constant.
struct Known<'a> {
    module: &'a Module,
    expressions: &'a Arena<Expression>,
    returns: &'a HashMap<Handle<Function>, bool>,
    variables: HashMap<Handle<LocalVariable>, bool>,
}

/// Prunes `function` until nothing changes; returns the constant it always returns, if any.
fn prune_function(module: &Module, returns: &HashMap<Handle<Function>, bool>, function: &mut Function) -> Option<bool> {
    loop {
        let known =
            Known { module, expressions: &function.expressions, returns, variables: constant_variables(function) };
        if !prune(&known, &mut function.body) {
            // Compaction keeps every named expression, also those of removed branches, which
            // may name the result of a call to a function no longer called; names are only
            // debug information.
            function.named_expressions.clear();
            let mut values = Vec::new();
            collect_returns(&known, &function.body, &mut values);
            return match values.split_first() {
                Some((&Some(first), rest)) if rest.iter().all(|&v| v == Some(first)) => Some(first),
                _ => None,
            };
        }
    }
}

/// Replaces, throughout `block`, each `if` with a constant condition by the branch it takes and
/// each `switch` on a constant by its case; returns whether anything changed.
fn prune(known: &Known, block: &mut Block) -> bool {
    let mut changed = false;
    for statement in block.iter_mut() {
        if let Statement::If { condition, accept, reject } = statement
            && let Some(taken) = known.bool(*condition)
        {
            let body = std::mem::take(if taken { accept } else { reject });
            *statement = Statement::Block(body);
            changed = true;
        }
        if let Statement::Switch { selector, cases } = statement
            && cases.len() > 1
            && let Some(value) = known.integer(*selector)
        {
            let matches = |case: &naga::SwitchCase| match case.value {
                SwitchValue::I32(v) => i64::from(v) == value,
                SwitchValue::U32(v) => i64::from(v) == value,
                SwitchValue::Default => false,
            };
            let chosen =
                cases.iter().position(matches).or_else(|| cases.iter().position(|c| c.value == SwitchValue::Default));
            // A case that falls through would take the next one's body along; left as it is.
            if let Some(i) = chosen
                && !cases[i].fall_through
            {
                let mut case = cases.swap_remove(i);
                case.value = SwitchValue::Default;
                *cases = vec![case];
                changed = true;
            }
        }
        changed |= match statement {
            Statement::Block(body) => prune(known, body),
            Statement::If { accept, reject, .. } => prune(known, accept) | prune(known, reject),
            Statement::Switch { cases, .. } => cases.iter_mut().fold(false, |c, case| prune(known, &mut case.body) | c),
            Statement::Loop { body, continuing, .. } => prune(known, body) | prune(known, continuing),
            _ => false,
        };
    }
    changed
}

impl Known<'_> {
    /// The value of boolean expression `handle` where it is known at this point.
    fn bool(&self, handle: Handle<Expression>) -> Option<bool> {
        match self.expressions[handle] {
            Expression::Literal(Literal::Bool(b)) => Some(b),
            Expression::Constant(c) => match self.module.global_expressions[self.module.constants[c].init] {
                Expression::Literal(Literal::Bool(b)) => Some(b),
                _ => None,
            },
            Expression::Unary { op: UnaryOperator::LogicalNot, expr } => self.bool(expr).map(|b| !b),
            Expression::Binary { op: op @ (BinaryOperator::LogicalAnd | BinaryOperator::LogicalOr), left, right } => {
                // The value that decides the operator alone: false for &&, true for ||.
                let decisive = op == BinaryOperator::LogicalOr;
                match (self.bool(left), self.bool(right)) {
                    (Some(a), _) if a == decisive => Some(decisive),
                    (_, Some(b)) if b == decisive => Some(decisive),
                    (Some(_), Some(_)) => Some(!decisive),
                    _ => None,
                }
            }
            Expression::Load { pointer } => match self.expressions[pointer] {
                Expression::LocalVariable(v) => self.variables.get(&v).copied(),
                _ => None,
            },
            Expression::CallResult(f) => self.returns.get(&f).copied(),
            _ => None,
        }
    }

    /// The value of integer expression `handle` where it is a literal or a constant.
    fn integer(&self, handle: Handle<Expression>) -> Option<i64> {
        let literal = match self.expressions[handle] {
            Expression::Literal(l) => l,
            Expression::Constant(c) => match self.module.global_expressions[self.module.constants[c].init] {
                Expression::Literal(l) => l,
                _ => return None,
            },
            _ => return None,
        };
        match literal {
            Literal::I32(v) => Some(v.into()),
            Literal::U32(v) => Some(v.into()),
            _ => None,
        }
    }
}

/// The unnamed `bool` variables of `function` (those of WGSL's short-circuit operators) that
/// are stored exactly once, with a constant, and otherwise only loaded.
fn constant_variables(function: &Function) -> HashMap<Handle<LocalVariable>, bool> {
    let candidates: Vec<Handle<LocalVariable>> =
        function.local_variables.iter().filter(|(_, v)| v.name.is_none() && v.init.is_none()).map(|(h, _)| h).collect();
    if candidates.is_empty() {
        return HashMap::new();
    }
    let variable = |pointer: Handle<Expression>| match function.expressions[pointer] {
        Expression::LocalVariable(v) => Some(v),
        _ => None,
    };
    // Per variable: its stores' constant values (None: not constant), or disqualified.
    let mut stores: HashMap<Handle<LocalVariable>, Option<Vec<Option<bool>>>> =
        candidates.iter().map(|&v| (v, Some(Vec::new()))).collect();
    let mut visit = |statement: &Statement| match *statement {
        Statement::Store { pointer, value } => {
            if let Some(v) = variable(pointer)
                && let Some(Some(values)) = stores.get_mut(&v)
            {
                // The stores of a short-circuit operator store the literal its left side decides
                // (`false` for &&, `true` for ||) or the right side's value.
                values.push(match function.expressions[value] {
                    Expression::Literal(Literal::Bool(b)) => Some(b),
                    _ => None,
                });
            }
        }
        Statement::Call { ref arguments, .. } => {
            for &a in arguments {
                if let Some(v) = variable(a) {
                    stores.insert(v, None);
                }
            }
        }
        _ => {}
    };
    walk(&function.body, &mut visit);
    stores
        .into_iter()
        .filter_map(|(v, values)| match values.as_deref() {
            Some([Some(b)]) => Some((v, *b)),
            _ => None,
        })
        .collect()
}

/// Calls `visit` on every statement of `block`, nested ones included.
fn walk(block: &Block, visit: &mut impl FnMut(&Statement)) {
    for statement in block.iter() {
        visit(statement);
        match statement {
            Statement::Block(body) => walk(body, visit),
            Statement::If { accept, reject, .. } => {
                walk(accept, visit);
                walk(reject, visit);
            }
            Statement::Switch { cases, .. } => cases.iter().for_each(|case| walk(&case.body, visit)),
            Statement::Loop { body, continuing, .. } => {
                walk(body, visit);
                walk(continuing, visit);
            }
            _ => {}
        }
    }
}

/// The constant value of every `return` in `block` (None where it returns nothing or a value
/// not known).
fn collect_returns(known: &Known, block: &Block, values: &mut Vec<Option<bool>>) {
    walk(block, &mut |statement| {
        if let Statement::Return { value } = *statement {
            values.push(value.and_then(|v| known.bool(v)));
        }
    });
}
