"""Benchmark models: shapes from the input, no lazy layers, width scaling, DENALI's variants per task."""

import pytest
import torch
from torch import nn

from nlosplan.errors import UserError
from nlosplan.tasks.models import MODEL_NAMES, ModelSpec, build_model, model_from_spec, n_parameters


@pytest.mark.parametrize("name", MODEL_NAMES)
@pytest.mark.parametrize("task,n_out", [("loc", 2), ("shape", 30), ("size", 2)])
@pytest.mark.parametrize("shape", [(3, 3, 128), (8, 8, 32), (1, 1, 48)])
def test_output_shape_and_no_lazy_layers(name, task, n_out, shape):
    torch.manual_seed(0)
    m = build_model(name, task, shape, n_out, width=0.125)
    assert not any(isinstance(mod, nn.modules.lazy.LazyModuleMixin) for mod in m.modules())
    m.eval()
    out = m(torch.randn(5, *shape))
    assert out.shape == (5, n_out) and torch.isfinite(out).all()


def test_full_width_is_the_papers_size():
    mlp = build_model("mlp", "shape", (3, 3, 128), 30)
    linears = [m for m in mlp.modules() if isinstance(m, nn.Linear)]
    assert [lin.out_features for lin in linears] == [512, 256, 128, 30]
    assert linears[0].in_features == 3 * 3 * 128
    cnn = build_model("cnn1d", "shape", (3, 3, 128), 30)
    convs = [m for m in cnn.modules() if isinstance(m, nn.Conv1d)]
    assert [(c.in_channels, c.out_channels, c.kernel_size[0]) for c in convs] == [(9, 128, 5), (128, 128, 3),
                                                                                 (128, 64, 3)]
    tr = build_model("transformer", "shape", (3, 3, 128), 30)
    layer = tr.encoder.layers[0]
    assert tr.d_model == 256 and len(tr.encoder.layers) == 4 and layer.self_attn.num_heads == 8
    assert layer.linear1.out_features == 1024 and tr.pos_encoding.shape == (1, 128, 256)


def test_cnn3d_variant_follows_denali_per_task():
    shape_net = build_model("cnn3d", "shape", (3, 3, 128), 30)
    deep = build_model("cnn3d", "size", (3, 3, 128), 2)
    k_shape = [m.kernel_size for m in shape_net.modules() if isinstance(m, nn.Conv3d)]
    k_deep = [m.kernel_size for m in deep.modules() if isinstance(m, nn.Conv3d)]
    assert k_shape == [(5, 5, 16)] and k_deep == [(3, 3, 10)] * 3


def test_width_scales_parameters():
    small = n_parameters(build_model("cnn1d", "shape", (3, 3, 128), 30, width=0.25))
    full = n_parameters(build_model("cnn1d", "shape", (3, 3, 128), 30, width=1.0))
    assert small < full / 8


def test_spec_round_trip_rebuilds_the_same_architecture():
    spec = ModelSpec("transformer", "loc", (3, 3, 64), 2, width=0.125, dropout=0.0)
    assert ModelSpec.from_dict(spec.to_dict()) == spec
    a, b = model_from_spec(spec), model_from_spec(spec)
    assert a.state_dict().keys() == b.state_dict().keys()
    b.load_state_dict(a.state_dict(), strict=True)


@pytest.mark.parametrize("kw,match", [
    (dict(name="resnet"), "unknown model"),
    (dict(task="depth"), "unknown task"),
    (dict(n_outputs=3), "n_outputs must be 2"),
    (dict(width=0.0), "width"),
    (dict(input_shape=(3, 128)), "input shape"),
])
def test_bad_arguments_are_user_errors(kw, match):
    args = dict(name="mlp", task="loc", input_shape=(3, 3, 128), n_outputs=2) | kw
    with pytest.raises(UserError, match=match):
        build_model(args.pop("name"), args.pop("task"), args.pop("input_shape"), args.pop("n_outputs"), **args)
