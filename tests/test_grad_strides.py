"""lfbench.training.distributed.match_grad_strides: a gradient that differs from its parameter only in the strides of
size-1 dimensions (a channels-last 1x1 weight used as a matrix) is given the parameter's strides without a copy;
every other gradient is left as autograd made it. (The two-process runs of tests/test_ddp_networks.py check that
DistributedDataParallel no longer warns.)"""

from __future__ import annotations

import torch

from lfbench.training.distributed import match_grad_strides


def _weight_1x1() -> torch.nn.Parameter:
    return torch.nn.Parameter(torch.arange(12.0).reshape(4, 3, 1, 1).to(memory_format=torch.channels_last))


def _matrix_loss(weight: torch.Tensor) -> torch.Tensor:
    x = torch.tensor([[1.0, -2.0], [0.5, 3.0], [2.0, 1.0]])
    return (weight.flatten(1) @ x).square().sum()


def test_a_1x1_weight_gets_its_own_strides_and_the_same_values():
    plain, hooked = _weight_1x1(), _weight_1x1()
    assert plain.stride() == (3, 1, 3, 3)
    _matrix_loss(plain).backward()
    assert plain.grad.stride() == (3, 1, 1, 1)  # what autograd gives: the case DDP warned about

    module = torch.nn.Module()
    module.weight = hooked
    match_grad_strides(module)
    _matrix_loss(hooked).backward()
    assert hooked.grad.stride() == hooked.stride() == (3, 1, 3, 3)
    assert torch.equal(hooked.grad, plain.grad)
    # d/dW of sum((W x)^2) = 2 (W x) x^T, by hand for row 0: W0 = (0, 1, 2)
    wx = torch.tensor([0 * 1 + 1 * 0.5 + 2 * 2, 0 * -2 + 1 * 3 + 2 * 1])
    expected_row0 = 2 * torch.stack([wx @ torch.tensor([1.0, -2.0]), wx @ torch.tensor([0.5, 3.0]),
                                     wx @ torch.tensor([2.0, 1.0])])
    torch.testing.assert_close(hooked.grad[0, :, 0, 0], expected_row0)


def test_a_gradient_of_another_layout_is_left_as_it_is():
    """Strides that differ where a dimension is larger than 1 are another memory order: no view can fix them."""
    weight = torch.nn.Parameter(torch.ones(2, 3, 2, 2))  # contiguous
    module = torch.nn.Module()
    module.weight = weight
    match_grad_strides(module)
    grad = torch.arange(24.0).reshape(2, 3, 2, 2).to(memory_format=torch.channels_last)
    weight.backward(grad)
    assert torch.equal(weight.grad, grad)
    assert weight.grad.stride() in (grad.stride(), weight.stride())  # autograd's contract decides, not the hook


def test_accumulated_gradients_keep_the_strides():
    weight = _weight_1x1()
    module = torch.nn.Module()
    module.weight = weight
    match_grad_strides(module)
    _matrix_loss(weight).backward()
    first = weight.grad.clone()
    _matrix_loss(weight).backward()
    assert weight.grad.stride() == weight.stride()
    assert torch.equal(weight.grad, 2 * first)


def test_removed_hooks_leave_gradients_as_autograd_makes_them():
    """Each stage's DDP gets its own hooks (the training loop removes the previous stage's): a removed hook no longer
    restrides."""
    weight = _weight_1x1()
    module = torch.nn.Module()
    module.weight = weight
    handles = match_grad_strides(module)
    assert len(handles) == 1
    for handle in handles:
        handle.remove()
    _matrix_loss(weight).backward()
    assert weight.grad.stride() == (3, 1, 1, 1)
