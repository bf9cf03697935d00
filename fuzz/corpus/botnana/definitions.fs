: sq dup * ;
: sum-sq 0 swap 0 do i sq + loop ;
4 sum-sq .
variable v 42 v ! v @ . 7 v +! v @ .
10 constant ten ten .
